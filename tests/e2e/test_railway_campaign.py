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
