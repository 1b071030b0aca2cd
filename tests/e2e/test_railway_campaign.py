"""The railway campaign (scenarios/railway/campaign.toml) in a reduced form: its diagonal (three
of the nine cruise speed x braking variants) for the first 60 s, every run with its own OpenRails
mock, bridge, balise FMU and map server on free ports. Each run's balise detections agree with
the track model; the faster the train, the farther it gets and the more balises it passes."""

from __future__ import annotations

import csv
from dataclasses import replace
from pathlib import Path

import pytest

from coupler_orchestrator.tools.campaign import CampaignSpec, run_campaign

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
async def test_the_railway_campaign_on_a_short_stop_time(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(ROOT)
    spec = CampaignSpec.load(ROOT / "scenarios" / "railway" / "campaign.toml")
    assert len(spec.variants) == 9
    spec = replace(
        spec,
        out=tmp_path,
        variants=spec.variants[::4],
        scenario=replace(spec.scenario, stop_time=60.0, timeout=300),
    )
    result = await run_campaign(spec, jobs=2)
    assert not result.failed, [(r.status, r.reason) for r in result.reports]
    with result.table_csv.open(encoding="utf-8", newline="") as file:
        rows = list(csv.DictReader(file))
    speeds = [float(r["Driver.target_speed"]) for r in rows]
    assert speeds == sorted(speeds) and len(set(speeds)) == 3
    for row in rows:
        assert row["detections_match_track"] == "true", row
        assert row["all_balises"] == "false"  # 60 s are not the whole line
        assert int(row["balises_total"]) == 77
        assert (
            float(row["top_speed_mps"]) <= float(row["Driver.target_speed"]) + 1.0
        )  # the driver overshoots a little
    distances = [float(r["distance_m"]) for r in rows]
    assert distances == sorted(distances) and distances[0] > 300
    expected = [int(r["balises_expected"]) for r in rows]
    assert expected[0] >= 1 and expected == sorted(expected)


PERCEPTION = """
[scenario]
fleet = "scenarios/railway/perception-fleet.toml"
stop_time = 40.0
timeout = 300
keep_services = {keep}

[[variant]]
"OpenRails.weather" = "snow"
"OpenRails.season" = "winter"

[[variant]]
"OpenRails.visibility" = 40.0

[[variant]]
"Driver.target_speed" = 22.2222

[outputs]
recall = "reports.perception.recall"
detections = "reports.perception.detections"
distance_m = "OpenRails.distance"
last_balise = "TrackBalises.last_balise_id"
"""


@pytest.mark.slow
@pytest.mark.timeout(900)
async def test_kept_railway_services_give_every_run_the_bytes_of_its_own(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The perception fleet kept up between runs (``keep_services = true``: the mock reset by
    the bridge at Initialize with the run's world, TrackBalises instantiated again, perception
    and the map empty again) gives each run the results.csv, byte for byte, and the perception
    report of the same run on services of its own, whatever ran on them before."""
    monkeypatch.chdir(ROOT)
    tables, runs = {}, {}
    for keep in ("true", "false"):
        path = tmp_path / f"keep-{keep}.toml"
        path.write_text(PERCEPTION.format(keep=keep), encoding="utf-8")
        spec = replace(CampaignSpec.load(path), out=tmp_path / keep)
        result = await run_campaign(spec, jobs=1)
        assert not result.failed, [(r.status, r.reason) for r in result.reports]
        with result.table_csv.open(encoding="utf-8", newline="") as file:
            rows = list(csv.DictReader(file))
        tables[keep] = [{k: v for k, v in r.items() if k not in ("wall_time_s", "realtime_factor")}
                        for r in rows]  # fmt: skip
        runs[keep] = [spec.out / r["directory"] for r in rows]
    assert tables["true"] == tables["false"]
    for kept, own in zip(runs["true"], runs["false"], strict=True):
        assert (kept / "results.csv").read_bytes() == (own / "results.csv").read_bytes()
        assert (kept / "perception-report.csv").read_bytes() == (
            own / "perception-report.csv"
        ).read_bytes()
    assert len({r["detections"] for r in tables["true"]}) > 1  # the worlds differ
