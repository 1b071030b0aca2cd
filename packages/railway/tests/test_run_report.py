"""`coupler run` scores a perception run itself: the `coupler.reports` entry point of this
package writes perception-report.json/.csv into the run's folder and its summary goes into
summary.json (`reports.perception`).

    Perception (detections: BaliseDetections)   TrackBalises (passed_in_step: String)
              \\                                      /
               `coupler run` (a process) -- results.csv -- the report

Both participants play test_scoring's table (ROWS) over gRPC, one value per second.
"""

from __future__ import annotations

import csv
import json
import math
import subprocess
import sys
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from PIL import Image as PILImage

from coupler.channels import Causality, Channel, Description, RunSetup, Value, ValueType
from coupler.participant import Participant, Values
from coupler.testing import SystemStructure, remote, served_in_thread
from coupler.v1.railway_pb2 import TrainState
from coupler.v1.sensors_pb2 import CameraIntrinsics, Image
from coupler_railway.messages import BALISE_DETECTIONS, IMAGE, TRAIN_STATE

from .support import ROWS, detections

LOOPBACK = "grpc://127.0.0.1:{}"


def scored(*, perception: int | None, balises: int, camera: int | None = None) -> SystemStructure:
    """Perception (when served), TrackBalises and the camera (when served), each alone,
    0 .. 60 s."""
    components = [
        remote("Perception", LOOPBACK.format(perception), outputs=["detections"]),
        remote("TrackBalises", LOOPBACK.format(balises), outputs=["passed_in_step"]),
    ]
    if camera is not None:
        components.append(
            remote("OpenRails", LOOPBACK.format(camera), outputs=["front", "train_state"])
        )
    return SystemStructure("Scored", components[perception is None :], stop_time=60)


class Table(Participant):
    """One output channel playing a column of ROWS: its value at t, or ``empty``."""

    def __init__(self, name: str, channel: Channel, column: int, empty: Value) -> None:
        self.name, self.output, self.empty = name, channel, empty
        self.values = {round(row[0]): row[column] for row in ROWS}

    async def describe(self) -> Description:
        return Description(name=self.name, channels=(self.output,), implementation="tests.Table")

    async def initialize(self, setup: RunSetup) -> Values:
        return {self.output.name: self.values.get(0, self.empty)}

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        return {self.output.name: self.values.get(round(time + step), self.empty)}

    async def terminate(self, reason: str = "") -> None:
        pass


def test_coupler_run_writes_the_perception_report(tmp_path: Path) -> None:
    perception = Table(
        "Perception",
        Channel(
            name="detections",
            causality=Causality.OUTPUT,
            type=ValueType.BINARY,
            message_type=BALISE_DETECTIONS,
        ),
        1,
        detections(0.0),
    )
    balises = Table(
        "TrackBalises",
        Channel(name="passed_in_step", causality=Causality.OUTPUT, type=ValueType.STRING),
        2,
        "",
    )
    out = tmp_path / "run"
    with served_in_thread(perception) as one, served_in_thread(balises) as two:
        ssd = scored(perception=one.port, balises=two.port).write(tmp_path / "scored.ssd")
        coupler = Path(sys.executable).with_name("coupler")
        done = subprocess.run(
            [str(coupler), "run", str(ssd), "--step", "1", "--out", str(out)],
            capture_output=True,
            text=True,
            timeout=120,
            stdin=subprocess.DEVNULL,
        )
    assert done.returncode == 0, done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed"
    report = summary["reports"]["perception"]
    assert (report["perception"], report["ground_truth"]) == ("Perception", "TrackBalises")
    assert (report["balises_passed"], report["balises_detected"]) == (3, 2)
    assert report["recall"] == pytest.approx(2 / 3, abs=1e-4)
    assert report["precision"] == pytest.approx(0.6)
    assert report["missed"] == [3]
    assert report["files"] == [
        "perception-report.json",
        "perception-report.csv",
        "perception-detections.csv",
        "perception-by-distance.csv",
        "perception-detections.parquet",
    ]
    written = json.loads((out / "perception-report.json").read_text())
    assert written["recall"] == report["recall"] and len(written["balises"]) == 3
    # the Parquet table holds the CSV's rows, typed, an empty cell as null
    table = pq.read_table(out / "perception-detections.parquet")
    with (out / "perception-detections.csv").open(newline="") as file:
        rows = list(csv.DictReader(file))
    assert table.num_rows == len(rows) == 5
    kinds = {"sensor": "string", "outcome": "string", "frame": "string", "left": "int64",
             "balise_id": "int64", "error_m": "double", "time_s": "double"}  # fmt: skip
    for name, kind in kinds.items():
        assert str(table.schema.field(name).type) == kind, name
    for name in table.column_names:
        values = table.column(name).to_pylist()
        for cell, value in zip((r[name] for r in rows), values, strict=True):
            if cell == "":
                assert value in (None, ""), (name, value)
            else:
                assert value == type(value)(cell), (name, cell, value)
    assert (out / "perception-report.csv").read_text().count("\n") == 4  # header + 3 balises


def test_a_run_without_detections_has_no_report(tmp_path: Path) -> None:
    balises = Table(
        "TrackBalises",
        Channel(name="passed_in_step", causality=Causality.OUTPUT, type=ValueType.STRING),
        2,
        "",
    )
    out = tmp_path / "run"
    with served_in_thread(balises) as server:
        ssd = scored(perception=None, balises=server.port).write(tmp_path / "plain.ssd")
        coupler = Path(sys.executable).with_name("coupler")
        done = subprocess.run(
            [str(coupler), "run", str(ssd), "--step", "1", "--stop-time", "3", "--out", str(out)],
            capture_output=True,
            text=True,
            timeout=120,
            stdin=subprocess.DEVNULL,
        )
    assert done.returncode == 0, done.stderr
    assert "reports" not in json.loads((out / "summary.json").read_text())
    assert not (out / "perception-report.json").exists()


class Camera(Participant):
    """The train's camera and odometry: an 80 x 60 grey frame and a TrainState at every step,
    the train at 12 m/s."""

    WIDTH, HEIGHT = 80, 60

    async def describe(self) -> Description:
        out, binary = Causality.OUTPUT, ValueType.BINARY
        channels = (
            Channel(name="front", causality=out, type=binary, message_type=IMAGE),
            Channel(name="train_state", causality=out, type=binary, message_type=TRAIN_STATE),
        )
        return Description(name="OpenRails", channels=channels, implementation="tests.Camera")

    def at(self, time: float) -> Values:
        focal = self.HEIGHT / 2 / math.tan(math.radians(22.5))
        frame = Image(
            sensor="front", time_s=time, width=self.WIDTH, height=self.HEIGHT, encoding="rgb8",
            intrinsics=CameraIntrinsics(fx=focal, fy=focal, cx=39.5, cy=29.5),
            data=bytes([128]) * (self.WIDTH * self.HEIGHT * 3),
        )  # fmt: skip
        state = TrainState(time_s=time, distance_m=12.0 * time)
        return {"front": frame.SerializeToString(), "train_state": state.SerializeToString()}

    async def initialize(self, setup: RunSetup) -> Values:
        return self.at(0.0)

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        return self.at(time + step)

    async def terminate(self, reason: str = "") -> None:
        pass


def test_the_run_keeps_the_frames_around_misses_and_false_detections_and_draws_them(
    tmp_path: Path,
) -> None:
    """Without asking for any frame: the run keeps those around detections and undetected
    passes (kept-frames/), the report draws the miss's and the false detections' and removes
    the rest; the rows link them."""
    perception = Table(
        "Perception",
        Channel(name="detections", causality=Causality.OUTPUT, type=ValueType.BINARY,
                message_type=BALISE_DETECTIONS),
        1,
        detections(0.0),
    )  # fmt: skip
    balises = Table(
        "TrackBalises",
        Channel(name="passed_in_step", causality=Causality.OUTPUT, type=ValueType.STRING),
        2,
        "",
    )
    out = tmp_path / "run"
    with (
        served_in_thread(perception) as one,
        served_in_thread(balises) as two,
        served_in_thread(Camera()) as three,
    ):
        structure = scored(perception=one.port, balises=two.port, camera=three.port)
        ssd = structure.write(tmp_path / "scored.ssd")
        coupler = Path(sys.executable).with_name("coupler")
        done = subprocess.run(
            [str(coupler), "run", str(ssd), "--step", "1", "--out", str(out)],
            capture_output=True,
            text=True,
            timeout=120,
            stdin=subprocess.DEVNULL,
        )
    assert done.returncode == 0, done.stderr
    report = json.loads((out / "summary.json").read_text())["reports"]["perception"]
    assert report["missed"] == [3]
    # the camera: 20.4 m along the line at 0 m travelled (the first detection says so), so
    # balise 3 (600 m, passed at 50 s) was 39.6, 27.6 and 15.6 m ahead at 45, 46 and 47 s
    with (out / "perception-report.csv").open() as handle:
        missed = next(row for row in csv.DictReader(handle) if row["balise_id"] == "3")
    assert missed["frames"].split() == [
        "perception-frames/t0045.0.png", "perception-frames/t0046.0.png",
        "perception-frames/t0047.0.png",
    ]  # fmt: skip
    with (out / "perception-detections.csv").open() as handle:
        false = [row["frame"] for row in csv.DictReader(handle) if row["outcome"] == "false"]
    assert false == ["perception-frames/t0020.0.png", "perception-frames/t0055.0.png"]
    drawn = sorted(p.name for p in (out / "perception-frames").iterdir())
    assert drawn == ["t0020.0.png", "t0045.0.png", "t0046.0.png", "t0047.0.png", "t0055.0.png"]
    assert report["frames_drawn"] == 5
    assert not list((out / "kept-frames").glob("*/*.png"))  # the frames kept: removed once drawn
    # scored again: the same report, its frames linked (the kept frames' index stays)
    again = subprocess.run(
        [sys.executable, "-m", "coupler_railway.scoring", str(out)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert again.returncode == 0, again.stderr
    rescored = json.loads((out / "perception-report.json").read_text())
    assert rescored["by_distance"] == report["by_distance"] and rescored["frames_drawn"] == 5
    assert rescored["balises"][2]["frames"].split()[0] == "perception-frames/t0045.0.png"
    assert not (out / "frames").exists()  # and no frame recorded otherwise
    with PILImage.open(out / "perception-frames" / "t0046.0.png") as picture:
        assert picture.size == (80, 60)
        pixels = np.asarray(picture.convert("RGB")).reshape(-1, 3)
    assert any(tuple(p) == (40, 140, 255) for p in pixels)  # the truth's box is drawn


@pytest.mark.slow  # about 10 s on two busy cores: a campaign of two runs
def test_a_campaign_table_holds_each_runs_perception_report(tmp_path: Path) -> None:
    """campaign.csv's outputs read summary.json's reports: recall, precision, an item of the
    bins; the run's frames come back with its folder."""
    perception = Table(
        "Perception",
        Channel(name="detections", causality=Causality.OUTPUT, type=ValueType.BINARY,
                message_type=BALISE_DETECTIONS),
        1,
        detections(0.0),
    )  # fmt: skip
    balises = Table(
        "TrackBalises",
        Channel(name="passed_in_step", causality=Causality.OUTPUT, type=ValueType.STRING),
        2,
        "",
    )
    with (
        served_in_thread(perception) as one,
        served_in_thread(balises) as two,
        served_in_thread(Camera()) as three,
    ):
        ssd = scored(perception=one.port, balises=two.port, camera=three.port).write(
            tmp_path / "scored.ssd"
        )
        campaign = tmp_path / "campaign.toml"
        campaign.write_text(
            f'[scenario]\nssp = "{ssd}"\nout = "{tmp_path / "out"}"\nargs = ["--step", "1"]\n\n'
            "[[variant]]\nstop_time = 60.0\n[[variant]]\nstop_time = 30.0\n\n"
            '[outputs]\nrecall = "reports.perception.recall"\n'
            'precision = "reports.perception.precision"\n'
            'recall_20_30 = "reports.perception.by_distance.2.recall"\n'
            'nothing = "reports.perception.no_such_figure"\n\n'
            '[pool]\nenv = [{ ONE = "1" }]\n'
        )
        done = subprocess.run(
            [str(Path(sys.executable).with_name("coupler")), "campaign", str(campaign)],
            capture_output=True,
            text=True,
            timeout=300,
            stdin=subprocess.DEVNULL,
        )
    assert done.returncode == 0, done.stdout + done.stderr
    with (tmp_path / "out" / "campaign.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert [(r["recall"], r["precision"], r["nothing"]) for r in rows] == [
        ("0.6667", "0.6", ""),  # to 60 s: balise 3 missed, two false detections
        ("1.0", "0.75", ""),  # to 30 s: balise 3 not yet passed, one false detection
    ]
    assert rows[0]["recall_20_30"] == "1.0"
    run = tmp_path / "out" / rows[0]["directory"]
    assert (run / "perception-frames" / "t0046.0.png").is_file()
