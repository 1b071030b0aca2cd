"""The multi-host tests' report: tables a test adds with the ``report`` fixture are printed at
the end of the pytest run (with or without ``-s``) and kept in test-artifacts/."""

from __future__ import annotations

from pathlib import Path

import pytest

ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts"
_REPORT = pytest.StashKey[list[str]]()


class Report:
    """Lines for the end of the run, also written to ``test-artifacts/<name>``."""

    def __init__(self, lines: list[str]) -> None:
        self._lines = lines

    def publish(self, name: str, text: str) -> Path:
        ARTIFACTS.mkdir(exist_ok=True)
        path = ARTIFACTS / name
        path.write_text(text + "\n", encoding="utf-8")
        self._lines += [*text.splitlines(), f"(kept in {path})", ""]
        return path


@pytest.fixture
def report(request: pytest.FixtureRequest) -> Report:
    return Report(request.config.stash.setdefault(_REPORT, []))


def pytest_terminal_summary(
    terminalreporter: pytest.TerminalReporter, config: pytest.Config
) -> None:
    lines = config.stash.get(_REPORT, [])
    if lines:
        terminalreporter.section("multi-host: cost per step against round-trip time")
        for line in lines:
            terminalreporter.write_line(line)
