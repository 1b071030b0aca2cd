"""Reference tables of the docs kept equal to the code they describe: a field added, renamed,
retyped or redescribed in the code fails here until the page says the same (the message holds
the table to paste).

- docs/participants.md "RunSetup": ``coupler.channels.RunSetup``'s fields, their types and
  their docstrings;
- docs/fleet.md: every table and key a fleet file may have (``tools.fleet``'s ``TABLES``,
  ``SCENARIO_KEYS``, ``SERVICE_KEYS``: what the loader accepts).
"""

from __future__ import annotations

import ast
import dataclasses
import inspect
import re
from pathlib import Path

from coupler.channels import RunSetup

ROOT = Path(__file__).resolve().parents[2]


def field_table(cls: type) -> str:
    """A Markdown table of a dataclass's fields: name, type as written, and its docstring
    (``code`` as `code`, on one line)."""
    tree = ast.parse(inspect.getsource(cls))
    body = tree.body[0]
    assert isinstance(body, ast.ClassDef)
    documented: dict[str, str] = {}
    for node, after in zip(body.body, body.body[1:], strict=False):
        if (
            isinstance(node, ast.AnnAssign)
            and isinstance(node.target, ast.Name)
            and isinstance(after, ast.Expr)
            and isinstance(after.value, ast.Constant)
            and isinstance(after.value.value, str)
        ):
            documented[node.target.id] = " ".join(after.value.value.split()).replace("``", "`")
    rows = ["| Field | Type | Meaning |", "| --- | --- | --- |"]
    for field in dataclasses.fields(cls):
        kind = str(field.type).replace("|", "\\|")
        rows.append(f"| `{field.name}` | `{kind}` | {documented.get(field.name, '')} |")
    return "\n".join(rows)


def test_the_runsetup_table_is_the_code() -> None:
    page = (ROOT / "docs" / "participants.md").read_text(encoding="utf-8")
    expected = field_table(RunSetup)
    assert all("| |" not in row[-3:] for row in expected.splitlines()), "a field without docstring"
    shown = re.search(r"(?ms)^\| Field \| Type \| Meaning \|$.*?(?=\n\n)", page)
    assert shown is not None, "docs/participants.md has no RunSetup table"
    assert shown.group(0) == expected, (
        f"docs/participants.md's RunSetup table should be:\n{expected}"
    )


def keys_of(page: str, heading: str) -> list[str]:
    """The first column of the table under ``heading`` (a ``## `` line) of ``page``."""
    section = page.split(f"\n## {heading}\n", 1)[1].split("\n## ", 1)[0]
    return re.findall(r"(?m)^\| `([^`]+)` \|", section)


def test_the_fleet_file_reference_lists_every_key_the_loader_knows() -> None:
    from coupler_orchestrator.tools.fleet import SCENARIO_KEYS, SERVICE_KEYS, TABLES

    page = (ROOT / "docs" / "fleet.md").read_text(encoding="utf-8")
    assert keys_of(page, "`[scenario]`") == list(SCENARIO_KEYS)
    assert keys_of(page, "`[[service]]`") == list(SERVICE_KEYS)
    assert [t for t in TABLES if f"\n## `[{t}]`\n" in page or f"\n## `[[{t}]]`\n" in page] == list(
        TABLES
    )
