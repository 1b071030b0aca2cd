"""What the localisation tests share besides fixtures (those are in conftest.py): the railML
lines.
"""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
TEST_LINE = ROOT / "packages/railway/tests/data/test-line.railml"
SCENARIO_LINE = ROOT / "scenarios/railway/data/annaberg-schwarzenberg.railml"
