"""Property-based: whatever a sensor configuration file holds, the mock (and the bridge, which
reads the same file) either take it or refuse it with the project's own error, naming the
file; never another exception.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from coupler.errors import ScenarioError
from openrails_bridge.sensors import load_sensors as bridge_sensors
from openrails_mock.sensors import load_sensors as mock_sensors

FUZZ = settings(
    max_examples=int(os.environ.get("COUPLER_FUZZ_EXAMPLES", "150")),
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)
GOOD = {"sensorName": "front", "sensorType": "rgb", "trainName": "PLAYER", "width": 800,
        "height": 600, "fov": 45.0}  # fmt: skip
VALUES = st.one_of(
    st.none(), st.booleans(), st.integers(-10**12, 10**12), st.floats(allow_nan=True),
    st.text(max_size=12), st.lists(st.integers(), max_size=3),
    st.dictionaries(st.text(), st.none()),
)  # fmt: skip
ENTRIES = st.one_of(
    st.dictionaries(st.sampled_from([*GOOD, "range", "extra"]), VALUES, max_size=8),
    st.builds(lambda changes: {**GOOD, **changes},
              st.dictionaries(st.sampled_from([*GOOD, "range"]), VALUES, max_size=3)),
    VALUES,
)  # fmt: skip


def check(text: str) -> None:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "sensors.json"
        path.write_text(text, encoding="utf-8")
        for load in (lambda: mock_sensors(path, train_name="PLAYER"), lambda: bridge_sensors(path)):
            try:
                load()
            except ScenarioError as exc:
                assert str(path) in str(exc)


@FUZZ
@given(st.lists(ENTRIES, max_size=4))
def test_any_json_is_taken_or_refused_by_name(entries: list[object]) -> None:
    check(json.dumps(entries))


@FUZZ
@given(st.text(max_size=200))
def test_any_text_is_taken_or_refused_by_name(text: str) -> None:
    check(text)
