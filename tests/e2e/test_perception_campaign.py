"""The perception campaign (scenarios/railway/perception-campaign.toml) in a reduced form: two
of its variants (clear noon; 23:00 in 12 m fog with dirty, snowed-over balises) for the first
48 s (the five balises at 120-326 m), on the local Dask cluster, twice. The second campaign
writes the same campaign.csv byte for byte (``[scenario] timings = false``: no wall times in
it); the clear run finds every balise, the foggy night with dirty, snowed-over balises fewer
than half, and the envelope links that run's misses to their frames."""

from __future__ import annotations

import csv
import io
from dataclasses import replace
from pathlib import Path

import pytest

from coupler_orchestrator.tools.campaign import CampaignSpec, run_campaign
from coupler_railway.envelope import read_campaign, write_envelope

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
@pytest.mark.timeout(900)
async def test_the_perception_campaign_twice_gives_the_same_table(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(ROOT)
    spec = CampaignSpec.load(ROOT / "scenarios" / "railway" / "perception-campaign.toml")
    assert len(spec.variants) >= 30 and not spec.timings
    clear, adverse = spec.variants[0], spec.variants[31]  # the [grid]'s first and last
    assert clear["OpenRails.visibility"] == 10000.0 and adverse["OpenRails.visibility"] == 12.0
    tables = []
    for attempt in ("first", "second"):
        reduced = replace(
            spec,
            out=tmp_path / attempt,
            variants=[clear, adverse],
            scenario=replace(spec.scenario, stop_time=48.0, timeout=600, health_timeout=240),
        )
        result = await run_campaign(reduced, jobs=2, scheduler="local")
        assert not result.failed, [(r.status, r.reason) for r in result.reports]
        tables.append(result.table_csv.read_bytes())
    assert tables[0] == tables[1]
    rows = list(csv.DictReader(io.StringIO(tables[0].decode("utf-8"))))
    assert "wall_time_s" not in rows[0]
    assert [r["balises"] for r in rows] == ["5", "5"]
    assert float(rows[0]["recall"]) == 1.0
    assert float(rows[1]["recall"]) < 0.5

    envelope = read_campaign(tmp_path / "first")
    # all four conditions differ between the two runs; both name the colour detector
    assert envelope.axes == [k for k in clear if k != "Perception.detector"]
    assert envelope.detectors == ["colour"]
    written = write_envelope(tmp_path / "first")
    page = written[0].read_text(encoding="utf-8")
    assert "perception-frames/" in page  # the foggy night's misses link to their frames
