"""OpenRails-for-simulation's JSON configuration files (sensors, other trains), read safely.

The simulation build is started with small JSON files: its sensors and the other trains. The
OpenRails mock and the bridge both read them; ``read_json`` reads one so that any file gives
either the parsed value or one ``ScenarioError`` line naming the file (and the line where
there is one) and the fix: never a traceback, never memory in proportion to a huge file.
"""

from __future__ import annotations

import json
from pathlib import Path

from coupler.errors import ScenarioError

MAX_CONFIG_BYTES = 1024 * 1024
"""Largest configuration file read: a sensor takes about 150 bytes, a train about 120."""


def read_json(path: Path, *, what: str, setting: str, max_bytes: int = MAX_CONFIG_BYTES) -> object:
    """The parsed JSON of ``path``; ScenarioError otherwise. ``what`` names the file's role
    ("sensor configuration"), ``setting`` where it was configured (``--sensors``)."""
    try:
        with path.open("rb") as file:
            raw = file.read(max_bytes + 1)
    except OSError as exc:
        raise ScenarioError(
            f"cannot read the {what} {path} ({setting}): {exc.strerror or exc}"
        ) from exc
    if len(raw) > max_bytes:
        raise ScenarioError(
            f"{path}: the {what} is larger than {max_bytes} bytes, more than any such file "
            f"needs; give a file with the entries the simulation uses"
        )
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        raise ScenarioError(
            f"{path}:{line}: the {what} is not UTF-8 text (byte 0x{raw[exc.start]:02x} at "
            f"offset {exc.start}); save it as UTF-8"
        ) from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise ScenarioError(
            f"{path}:{exc.lineno}: the {what} is not valid JSON: {exc.msg}"
        ) from None
    except RecursionError:
        raise ScenarioError(
            f"{path}: the {what} nests lists or objects too deeply to read; it is a list of "
            f"flat objects"
        ) from None
