"""Reading MSTS/OpenRails STF text files: a SIMISA header line, then ``Token ( ... )`` blocks.

A file is a list of items; an item is a bare word or number, a quoted string, or a block
``Name ( items )``. The mock reads the route folder files (route, track database, track
sections, paths, world, and the files OpenRails' viewer opens: :mod:`openrails_mock.content`)
as OpenRails does: UTF-16 with a byte order mark or UTF-8 (a UTF-16 file without its byte
order mark is refused, not read as nothing), any whitespace, ``//`` comments,
``comment``/``skip`` blocks ignored, names case-insensitive.
Every problem is a :class:`RouteError` naming the file and line.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

from coupler.errors import ScenarioError


class RouteError(ScenarioError):
    """A route folder the mock cannot load; the message names the file, the line and the fix."""

    def __init__(self, file: str | os.PathLike[str], line: int | None, problem: str, fix: str):
        self.file = str(file)
        self.line = line
        where = f"{self.file}:{line}" if line is not None else self.file
        super().__init__(f"{where}: {problem}; {fix}")


@dataclass
class Block:
    """``Name ( items )``: ``items`` are words/strings (str) and nested blocks, in order."""

    name: str
    line: int
    items: list[str | Block] = field(default_factory=list)
    file: str = ""

    @property
    def values(self) -> list[str]:
        """The words and strings of the block (nested blocks left out)."""
        return [i for i in self.items if isinstance(i, str)]

    def blocks(self, name: str) -> list[Block]:
        """Nested blocks called ``name`` (case-insensitive)."""
        wanted = name.lower()
        return [i for i in self.items if isinstance(i, Block) and i.name.lower() == wanted]

    def block(self, name: str) -> Block:
        """The one nested block ``name``; RouteError if it is missing."""
        found = self.blocks(name)
        if not found:
            raise self.error(f"{self.name} has no {name} block", f"add {name} ( ... )")
        return found[0]

    def optional(self, name: str) -> Block | None:
        found = self.blocks(name)
        return found[0] if found else None

    def error(self, problem: str, fix: str) -> RouteError:
        return RouteError(self.file, self.line, problem, fix)

    def _value(self, index: int, what: str) -> str:
        values = self.values
        if index >= len(values):
            raise self.error(
                f"{self.name} has {len(values)} values, but {what} is value {index + 1}",
                f"write {self.name} with all its values",
            )
        return values[index]

    def declared(self, child: str, what: str) -> list[Block]:
        """The nested ``child`` blocks, exactly as many as the block's first value declares
        (OpenRails reads that many; a count that disagrees is a damaged file)."""
        count = self.integer(0, f"the number of {what}")
        found = self.blocks(child)
        if count != len(found):
            raise self.error(
                f"{self.name} declares {count} {what} but holds {len(found)}",
                f"give the number of {child} blocks it holds",
            )
        return found

    def integer(self, index: int, what: str) -> int:
        text = self._value(index, what)
        try:
            return int(text)
        except ValueError:
            raise self.error(
                f"{what} of {self.name} is {text!r}, not an integer", "write a whole number"
            ) from None

    def real(self, index: int, what: str) -> float:
        text = self._value(index, what)
        try:
            value = float(text)
        except ValueError:
            value = float("nan")
        if value != value or value in (float("inf"), float("-inf")):
            raise self.error(f"{what} of {self.name} is {text!r}, not a number", "write a number")
        return value

    def text(self, index: int, what: str) -> str:
        return self._value(index, what)

    def hexadecimal(self, index: int, what: str) -> int:
        text = self._value(index, what)
        try:
            return int(text, 16)
        except ValueError:
            raise self.error(
                f"{what} of {self.name} is {text!r}, not hexadecimal flags", "write e.g. 00000000"
            ) from None


_IGNORED = {"comment", "skip"}
MAX_FILE_BYTES = 64 * 1024 * 1024
"""The largest route file read [bytes]: a big route's track database is a few MB; anything
near this is not one (a link to /dev/zero, a runaway file), refused before it is read whole."""


def _decode(path: Path, data: bytes) -> str:
    if data.startswith(b"\xff\xfe"):
        return data[2:].decode("utf-16-le")
    if data.startswith(b"\xfe\xff"):
        return data[2:].decode("utf-16-be")
    if data.startswith(b"\xef\xbb\xbf"):
        return data[3:].decode("utf-8")
    if len(data) >= 2 and (data[0] == 0) != (data[1] == 0):  # UTF-16 without its mark
        raise RouteError(
            path,
            1,
            "is UTF-16 text without its byte order mark (FF FE): OpenRails reads such a file "
            "as UTF-8 and finds nothing in it (its shape, terrain and world reader refuses it)",
            "write it as MSTS does: UTF-16 little endian starting with FF FE",
        )
    return data.decode("utf-8")


def _stf_text(file: Path) -> tuple[str, int]:
    """The file's text after its SIMISA header, and the line number that text starts on."""
    try:
        if not file.is_file():
            raise RouteError(
                file, None, "is not a regular file", "give the route's file, not a device or pipe"
            )
        with file.open("rb") as opened:
            data = opened.read(MAX_FILE_BYTES + 1)
        if len(data) > MAX_FILE_BYTES:
            raise RouteError(
                file,
                None,
                f"is larger than {MAX_FILE_BYTES // (1024 * 1024)} MB, more than any route file",
                "give the route's own file",
            )
    except OSError as exc:
        raise RouteError(
            file, None, f"cannot read it: {exc.strerror or exc}", "check the path"
        ) from exc
    try:
        text = _decode(file, data)
    except UnicodeDecodeError as exc:
        raise RouteError(
            file,
            None,
            f"is neither UTF-16 nor UTF-8 text ({exc.reason})",
            "write it as MSTS does: UTF-16 with a byte order mark",
        ) from None
    if text.startswith("SIMISA@@@@@@@@@@JINX0"):
        return (text.split("\n", 1)[1] if "\n" in text else ""), 2
    if text.lstrip().startswith("SIMISA"):
        raise RouteError(
            file, 1, "is a binary or compressed MSTS file", "save it as unicode text (ffeditc)"
        )
    return text, 1


def _quoted(file: Path, text: str, i: int, line: int) -> tuple[str, int, int]:
    """The quoted string whose opening ``"`` is at ``i``: its text, the index after its
    closing ``"`` and the line that closing quote is on."""
    start_line = line
    n = len(text)
    j = i + 1
    chars = []
    while j < n and text[j] != '"':
        if text[j] == "\\" and j + 1 < n:
            j += 1
            chars.append({"n": "\n", "t": "\t"}.get(text[j], text[j]))
        else:
            if text[j] == "\n":
                line += 1
            chars.append(text[j])
        j += 1
    if j >= n:
        raise RouteError(file, start_line, "a quoted string is not closed", 'add the "')
    return "".join(chars), j + 1, line


def _word_end(text: str, i: int) -> int:
    """The index after the unquoted word that starts at ``i``."""
    n = len(text)
    while i < n and not text[i].isspace() and text[i] not in '()"':
        i += 1
    return i


def read_stf(path: str | os.PathLike[str]) -> Block:
    """Parse an STF text file into a root :class:`Block` (name ``""``) of its items."""
    file = Path(path)
    text, line = _stf_text(file)
    root = Block("", 0, file=str(file))
    stack = [root]
    pending: tuple[str, int] | None = None  # a word that may name the next block
    i, n = 0, len(text)

    def flush() -> None:
        nonlocal pending
        if pending is not None:
            stack[-1].items.append(pending[0])
            pending = None

    while i < n:
        c = text[i]
        if c == "\n":
            line += 1
            i += 1
        elif c.isspace():
            i += 1
        elif c == "/" and text.startswith("//", i):
            while i < n and text[i] != "\n":
                i += 1
        elif c == "(":
            if pending is None:
                raise RouteError(file, line, "a block opens without a name", "write Name ( ... )")
            block = Block(pending[0], pending[1], file=str(file))
            pending = None
            stack[-1].items.append(block)
            stack.append(block)
            i += 1
        elif c == ")":
            flush()
            if len(stack) == 1:
                raise RouteError(file, line, "a ')' closes no block", "remove it or add the '('")
            closed = stack.pop()
            if closed.name.lower() in _IGNORED:
                stack[-1].items.remove(closed)
            i += 1
        elif c == '"':
            flush()
            # "a" + "b" joins strings, as in MSTS files
            word, i, line = _quoted(file, text, i, line)
            stack[-1].items.append(word)
        else:
            flush()
            j = _word_end(text, i)
            pending = (text[i:j], line)
            i = j
    flush()
    if len(stack) > 1:
        raise RouteError(
            file, stack[-1].line, f"block {stack[-1].name} is not closed", "add the ')'"
        )
    return root
