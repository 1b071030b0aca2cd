"""Sizes written in a sensor configuration file are bounded before anything is built, in the
mock and in the bridge (which reads the same file): the number of sensors, the file's size, its
nesting and its encoding each give one ScenarioError line naming the file, never a traceback.

    sensors.json --> openrails_mock.sensors.load_sensors / openrails_bridge.sensors.load_sensors
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import pytest

from coupler.errors import ScenarioError
from openrails_bridge.sensors import load_sensors as bridge_sensors
from openrails_mock.sensors import load_sensors as mock_sensors

MAX_SENSORS = 64
"""The documented limit (README: "Sensors"), the same in the mock and the bridge."""
READERS: dict[str, Callable[[Path], object]] = {
    "mock": lambda path: mock_sensors(path, train_name="PLAYER"),
    "bridge": bridge_sensors,
}


def entry(n: int) -> dict[str, object]:
    return {"sensorName": f"cam{n}", "sensorType": "rgb", "trainName": "PLAYER",
            "width": 8, "height": 6, "fov": 45.0}  # fmt: skip


def refused(read: Callable[[Path], object], path: Path) -> str:
    with pytest.raises(ScenarioError) as caught:
        read(path)
    message = str(caught.value)
    assert "\n" not in message and str(path) in message
    return message


@pytest.mark.parametrize("reader", READERS)
def test_more_sensors_than_the_limit_are_refused_before_any_is_checked(
    reader: str, tmp_path: Path
) -> None:
    path = tmp_path / "sensors.json"
    path.write_text(json.dumps([entry(n) for n in range(MAX_SENSORS)]))
    assert len(READERS[reader](path)) == MAX_SENSORS  # type: ignore[arg-type]
    path.write_text(json.dumps([entry(n) for n in range(MAX_SENSORS + 1)]))
    assert f"{MAX_SENSORS + 1} sensors, more than the {MAX_SENSORS}" in refused(
        READERS[reader], path
    )


@pytest.mark.parametrize("reader", READERS)
def test_a_huge_file_is_refused_unread(reader: str, tmp_path: Path) -> None:
    path = tmp_path / "sensors.json"
    path.write_text("[" + ", ".join(["1"] * 600_000) + "]")  # 1.8 MB of numbers
    assert "larger than 1048576 bytes" in refused(READERS[reader], path)


@pytest.mark.parametrize("reader", READERS)
def test_deep_nesting_is_a_one_line_error(reader: str, tmp_path: Path) -> None:
    path = tmp_path / "sensors.json"
    path.write_text("[" * 200_000 + "]" * 200_000)
    assert "nests lists or objects too deeply" in refused(READERS[reader], path)


@pytest.mark.parametrize("reader", READERS)
def test_a_latin1_file_names_the_line_and_the_byte(reader: str, tmp_path: Path) -> None:
    path = tmp_path / "sensors.json"
    text = json.dumps([{**entry(0), "sensorName": "caméra"}], indent=1, ensure_ascii=False)
    path.write_bytes(text.encode("latin-1"))
    message = refused(READERS[reader], path)
    assert f"{path}:3: the sensor configuration is not UTF-8 text (byte 0xe9" in message
