"""The operating envelope of a perception campaign, from a campaign folder laid out as
`coupler campaign` writes one (runs/<n>-<key>/variant.json, summary.json with
reports.perception, perception-frames/): charts against each varied parameter, a map over
two, boundaries at recall 0.9 and 0.5, the worst runs with links to their frames.

Here: fog visibility x sun elevation, recall falling with fog and at low sun; two detectors.
"""

from __future__ import annotations

import csv
import itertools
import json
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from coupler_railway.envelope import boundary, read_campaign, write_envelope

ROOT = Path(__file__).resolve().parents[3]
FOG = (50.0, 100.0, 200.0, 400.0)
SUN = (5.0, 20.0, 45.0)


def recall(fog: float, sun: float, detector: str) -> float:
    made = min(1.0, fog / 200.0) * (0.6 if sun < 10 else 1.0)
    return round(min(1.0, made * 1.5) if detector == "learned" else made, 3)


def write_run(folder: Path, n: int, variant: dict[str, object], value: float) -> None:
    """Run ``n`` as `coupler campaign` lays it out: its variant, its scored summary, a frame."""
    run = folder / "runs" / f"{n:03d}-key{n}"
    (run / "perception-frames").mkdir(parents=True)
    report = {"recall": value, "precision": 1.0, "max_abs_error_m": 2 - value,
              "mean_abs_error_m": 0.1}  # fmt: skip
    (run / "variant.json").write_text(json.dumps(variant))
    (run / "summary.json").write_text(json.dumps({"reports": {"perception": report}}))
    if value < 1:
        (run / "perception-frames" / "t0012.4.png").write_bytes(b"\x89PNG")


def campaign(folder: Path, key: str = "detector", default: str = "") -> Path:
    """Runs naming ``default`` leave the detector out of their variant (the participant's)."""
    n = 0
    for detector in ("colour", "learned"):
        for fog in FOG:
            for sun in SUN:
                named = {} if detector == default else {key: detector}
                variant = {**named, "OpenRails.fog_m": fog, "OpenRails.sun_deg": sun}
                write_run(folder, n, variant, recall(fog, sun, detector))
                n += 1
    (folder / "runs" / "999-failed").mkdir()  # a run that wrote nothing: left out
    return folder


def test_the_envelope_reads_the_runs_and_their_axes(tmp_path: Path) -> None:
    envelope = read_campaign(campaign(tmp_path))
    assert len(envelope.runs) == 24
    assert envelope.axes == ["OpenRails.fog_m", "OpenRails.sun_deg"]
    assert envelope.detectors == ["colour", "learned"]
    assert boundary([(50.0, 0.25), (100.0, 0.5), (200.0, 1.0)], 0.9) == [180.0]


def test_a_detector_named_as_a_parameter_and_the_default_are_series(tmp_path: Path) -> None:
    """A campaign that names the learned detector as ``Perception.detector`` and runs the
    colour one as the participant's default (no key): two series, neither an axis."""
    envelope = read_campaign(campaign(tmp_path, "Perception.detector", default="colour"))
    assert envelope.axes == ["OpenRails.fog_m", "OpenRails.sun_deg"]
    assert envelope.detectors == ["", "learned"]
    assert sum(r.detector == "learned" for r in envelope.runs) == 12


def test_the_perception_campaign_names_the_detector_of_every_run(tmp_path: Path) -> None:
    """scenarios/railway/perception-campaign.toml names the colour detector (its [grid]) as
    well as the learned one (its [table]): the legend says which detector each series is,
    none is "default"."""
    spec = tomllib.loads((ROOT / "scenarios/railway/perception-campaign.toml").read_text())
    grid = [dict(zip(spec["grid"], values, strict=True))
            for values in itertools.product(*spec["grid"].values())]  # fmt: skip
    with (ROOT / "scenarios/railway" / spec["table"]["file"]).open(encoding="utf-8") as handle:
        table = [{k: float(v) if k.startswith("OpenRails.") else v for k, v in row.items()}
                 for row in csv.DictReader(handle)]  # fmt: skip
    for n, variant in enumerate(grid + table):
        write_run(tmp_path, n, variant, 1.0 if variant["OpenRails.visibility"] > 100 else 0.0)
    envelope = read_campaign(tmp_path)
    assert len(envelope.runs) == 64 and envelope.detectors == ["colour", "learned"]
    assert "Perception.detector" not in envelope.axes
    write_envelope(tmp_path)
    page = (tmp_path / "envelope.html").read_text(encoding="utf-8")
    assert "detectors: colour, learned." in page and "default" not in page


def test_crossing_labels_each_have_a_line_of_their_own(tmp_path: Path) -> None:
    """Where the detectors' recall crosses 0.9 and 0.5 near one another, their labels at the
    top of the chart do not overlap: each is on a line of its own."""
    write_envelope(campaign(tmp_path))
    page = (tmp_path / "envelope.html").read_text(encoding="utf-8")
    label = re.compile(r'<text x="[\d.]+" y="([\d.]+)" font-size="9" [^>]*>0\.\d at')
    for chart in page.split("<svg")[1:]:
        lines = label.findall(chart)
        assert len(lines) == len(set(lines)), lines
    assert page.count(" at ") >= 3  # crossings of both detectors on one chart


def test_the_command_writes_html_png_and_csv_with_boundaries_and_frame_links(
    tmp_path: Path,
) -> None:
    folder = campaign(tmp_path / "campaign")
    done = subprocess.run(
        [str(Path(sys.executable).with_name("coupler-railway")), "envelope", str(folder)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    page = (folder / "envelope.html").read_text()
    assert "<script" not in page and "http" not in page.replace("http://www.w3.org", "")
    # the colour detector's mean recall over sun elevations crosses 0.9 and 0.5 along fog
    assert "0.9 at" in page and "0.5 at" in page
    assert page.count('stroke-width="3"') >= 2  # the map's boundaries, for each detector
    assert 'href="runs/000-key0/perception-frames/t0012.4.png"' in page  # the worst run
    assert (folder / "envelope.png").read_bytes()[:4] == b"\x89PNG"
    with (folder / "envelope.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 24 and rows[0]["recall"] == "0.15"


def test_a_folder_without_a_campaign_or_a_parameter_to_vary_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="no runs/ folder"):
        write_envelope(tmp_path)
    done = subprocess.run(
        [str(Path(sys.executable).with_name("coupler-railway")), "envelope", str(tmp_path),
         "--axes", "a", "b"],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert (
        done.returncode == 1
        and done.stderr.startswith("error: ")
        and "Traceback" not in (done.stderr)
    )
