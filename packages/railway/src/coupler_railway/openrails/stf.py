"""Writing MSTS/OpenRails STF text files: a SIMISA header, then ``Token ( values ... )`` blocks.

The files are UTF-16 little endian with a byte order mark and CR LF line ends, as MSTS writes
them and OpenRails reads them; blocks are indented with tabs. Numbers are written as OpenRails
reads them: integers in decimal, reals as the shortest text that reads back to the same
single-precision float.
"""

from __future__ import annotations

import os
import unicodedata
from pathlib import Path

import numpy as np

Value = int | float | str


def number(value: float) -> str:
    """The shortest decimal text of ``value`` rounded to single precision."""
    text = np.format_float_positional(np.float32(value), trim="-")
    return "0" if text in ("-0", "") else text


_ESCAPES = {"\\": "\\\\", '"': '\\"', "\n": "\\n", "\t": "\\t"}


def quote(text: str) -> str:
    """``text`` as an STF string: in double quotes; quotes, backslashes, newlines and tabs
    escaped as OpenRails' reader reads them (``\\n``, ``\\t``); any other control character
    (which no STF reader decodes) becomes a space."""
    return (
        '"'
        + "".join(_ESCAPES.get(c, " " if unicodedata.category(c) == "Cc" else c) for c in text)
        + '"'
    )


def _text(value: Value) -> str:
    if isinstance(value, bool):
        raise TypeError("STF has no booleans; write 0 or 1")
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return number(value)
    return value


class StfWriter:
    """Lines of one STF file; ``block`` opens ``Name (``, ``end`` closes it."""

    def __init__(self, signature: str) -> None:
        if len(signature) != 8 or not signature.startswith("JINX0"):
            raise ValueError(f"not an STF file signature: {signature!r}")
        self.header = f"SIMISA@@@@@@@@@@{signature}______"
        self.lines: list[str] = []
        self.depth = 0

    def line(self, name: str, *values: Value) -> None:
        """``Name ( values )`` on one line."""
        inner = "".join(_text(v) + " " for v in values)
        self.lines.append("\t" * self.depth + f"{name} ( {inner})")

    def values(self, *values: Value) -> None:
        """Bare values on one line (inside a block)."""
        self.lines.append("\t" * self.depth + " ".join(_text(v) for v in values))

    def block(self, name: str, *values: Value) -> None:
        """Open ``Name ( values`` over several lines; close it with :meth:`end`."""
        inner = "".join(" " + _text(v) for v in values)
        self.lines.append("\t" * self.depth + f"{name} ({inner}")
        self.depth += 1

    def end(self) -> None:
        self.depth -= 1
        if self.depth < 0:
            raise ValueError("end() without an open block")
        self.lines.append("\t" * self.depth + ")")

    def text(self) -> str:
        if self.depth:
            raise ValueError(f"{self.depth} block(s) left open")
        return "\r\n".join([self.header, "", *self.lines, ""])

    def save(self, path: str | os.PathLike[str]) -> Path:
        target = Path(path)
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(b"\xff\xfe" + self.text().encode("utf-16-le"))
        return target
