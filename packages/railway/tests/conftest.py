"""Shared fixtures: the hand-made test line and the Annaberg-Schwarzenberg scenario."""

from __future__ import annotations

from pathlib import Path

import pytest

from coupler_railway import Infrastructure, load_infrastructure

DATA = Path(__file__).parent / "data"
SCENARIO = Path(__file__).parents[3] / "scenarios" / "railway" / "data"


@pytest.fixture(scope="session")
def test_line() -> Infrastructure:
    return load_infrastructure(DATA / "test-line.railml")


@pytest.fixture(scope="session")
def scenario() -> Infrastructure:
    return load_infrastructure(SCENARIO / "annaberg-schwarzenberg.railml")
