"""Results are never overwritten silently: every run writes into a folder of its own.

    coupler run X.fmu            -> results/X/<UTC time>-<run id>/   (results/X/latest -> newest)
    coupler run X.fmu --out DIR  -> DIR, refused when DIR holds an earlier run (--force replaces)

Each command runs as the user runs it: ``coupler`` as a process, in a working folder of its own.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from ..support import Coupler


@pytest.mark.slow
def test_three_runs_without_out_leave_three_intact_folders(
    fmus: dict[str, Path], tmp_path: Path
) -> None:
    printed = []
    for stop in ("1", "2", "3"):
        outcome = Coupler.process(
            "run", fmus["Source2"], "--stop-time", stop, "--step", "0.5", cwd=tmp_path
        )
        assert outcome.code == 0, outcome.err
        [line] = [x for x in outcome.out.splitlines() if x.startswith("results: ")]
        printed.append(tmp_path / line.removeprefix("results: "))
    base = tmp_path / "results" / "Source2"
    # in the order the runs said (two runs in the same second have names that sort by their
    # random part, not by when they ran)
    folders = [p.parent for p in printed]
    assert all(p.parent == base for p in folders)  # each run said where it went
    assert sorted(folders) == sorted(p for p in base.iterdir() if not p.is_symlink())
    assert [len(Coupler.results(p)) for p in folders] == [3, 5, 7]  # none overwritten
    run_ids = {Coupler.summary(p)["run_id"] for p in folders}
    assert len(run_ids) == 3
    assert (base / "latest").is_symlink()
    assert (base / "latest").resolve() == folders[-1].resolve()
    assert os.readlink(base / "latest") == folders[-1].name  # relative: the folder may move


@pytest.mark.slow
def test_out_holding_an_earlier_run_is_refused_and_force_replaces_it(
    fmus: dict[str, Path], tmp_path: Path
) -> None:
    out = tmp_path / "out"
    first = Coupler.process(
        "run", fmus["Source2"], "--out", out, "--stop-time", "1", "--step", "0.5"
    )
    assert first.code == 0, first.err
    kept = (out / "results.csv").read_bytes()
    stale = out / "recordings" / "Source.crec"  # as an earlier run with --record leaves it
    stale.parent.mkdir()
    stale.write_bytes(b"an earlier run's recording")
    (out / "notes.txt").write_text("mine")

    again = Coupler.process(
        "run", fmus["Source2"], "--out", out, "--stop-time", "2", "--step", "0.5"
    )
    assert again.code == 1
    run_id = json.loads((out / "summary.json").read_text())["run_id"]
    assert again.err.strip().splitlines() == [
        f"error: {out} already holds the results of an earlier run (run {run_id}, completed); "
        "a run writes into a folder of its own: leave --out out (each run gets a new folder "
        "under results/<scenario>/, `latest` links to the newest), choose another --out, or "
        "add --force to replace them"
    ]
    assert (out / "results.csv").read_bytes() == kept  # untouched

    forced = Coupler.process(
        "run", fmus["Source2"], "--out", out, "--stop-time", "2", "--step", "0.5", "--force"
    )
    assert forced.code == 0, forced.err
    assert len(Coupler.results(out)) == 5
    assert not (out / "recordings").exists()  # nothing of the earlier run mixes with this one
    assert (out / "notes.txt").read_text() == "mine"  # what is not a run's file stays
