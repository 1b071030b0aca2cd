"""docs/orchestrator.md draws the orchestrator's folders ("How a run flows"); the folders are
what it draws: every module and folder of the package is on the map, and every name the map
puts at the start of a line is a module or folder that exists."""

from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[3]
PACKAGE = REPO / "services" / "orchestrator" / "src" / "coupler_orchestrator"


def stage_map() -> str:
    text = (REPO / "docs" / "orchestrator.md").read_text(encoding="utf-8")
    section = text.split("## How a run flows", 1)[1]
    return section.split("```", 2)[1]


def test_every_module_and_folder_is_on_the_map() -> None:
    words = set(re.findall(r"[A-Za-z_][A-Za-z0-9_]*", stage_map()))
    missing = [
        str(path.relative_to(PACKAGE))
        for path in sorted(PACKAGE.rglob("*"))
        if "__pycache__" not in path.parts
        and "ssp" not in path.relative_to(PACKAGE).parts[:-1]  # ssp/'s modules: its own docs
        and (path.suffix == ".py" or (path.is_dir() and any(path.glob("*.py"))))
        and not path.name.startswith("__")
        and path.stem not in words
    ]
    assert not missing, f"not on docs/orchestrator.md's map: {missing}"


def test_every_name_the_map_lists_exists() -> None:
    folder = PACKAGE
    absent = []
    for line in stage_map().splitlines()[2:]:
        match = re.match(r"^( {2}| {4})([a-z_]+)(/?)(?:, ([a-z_]+)/?)?\s", line + " ")
        if match is None:
            continue
        indent, name, slash, second = match.groups()
        parent = PACKAGE if indent == "  " else folder
        for each in filter(None, (name, second)):
            path = parent / each
            if not (path.is_dir() or path.with_suffix(".py").is_file()):
                absent.append(str(path.relative_to(PACKAGE)))
        if indent == "  ":
            folder = PACKAGE / name if slash else PACKAGE
    assert not absent, f"on the map, not in the package: {absent}"
