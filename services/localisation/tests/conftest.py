"""Shared helpers of the localisation service's tests: the railway package's test line as
linking data, and a train driven along it through the transmission and the estimator."""

from __future__ import annotations

import pytest

from localisation.linking import Linking

from .support import SCENARIO_LINE


@pytest.fixture(scope="session")
def line() -> Linking:
    return Linking.from_railml(SCENARIO_LINE)
