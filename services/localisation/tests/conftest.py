"""Shared helpers of the localisation service's tests: the railway package's test line as
linking data, and a train driven along it through the transmission and the estimator."""

from __future__ import annotations

from pathlib import Path

import pytest

from localisation.linking import Linking

ROOT = Path(__file__).resolve().parents[3]
TEST_LINE = ROOT / "packages/railway/tests/data/test-line.railml"
SCENARIO_LINE = ROOT / "scenarios/railway/data/annaberg-schwarzenberg.railml"


@pytest.fixture(scope="session")
def line() -> Linking:
    return Linking.from_railml(SCENARIO_LINE)
