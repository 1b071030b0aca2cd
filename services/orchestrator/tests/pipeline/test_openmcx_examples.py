"""OpenMCx's own five examples (eclipse/openmcx ``examples/``: getting_started, connections,
parameters, units, vector_ports, with the three FMUs OpenMCx's build makes from its own sources)
run unchanged with ``coupler run`` and equal the reference CSVs OpenMCx ships beside them.

Needs a local OpenMCx tree whose build made its FMUs (``fmus/*.fmu``): ``OPENMCX_SRC=TREE``
(docs/openmcx.md says how to build it); nothing of it is in this repository, so without it the
tests are skipped. Each example is checked twice: ``coupler run --openmcx-results`` writes the
files OpenMCx wrote (every file, header, unit line, row and time; numbers within 1e-9 of their
column's largest magnitude), and a plain ``coupler run`` records in results.csv the values of
every reference output at every reference time. The largest differences are printed (``-s``).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from coupler_orchestrator.ssp import load_ssp

from ..support import Coupler
from ..support.openmcx_files import TOLERANCE, differences, table

EXAMPLES = ("getting_started", "connections", "parameters", "units", "vector_ports")


@pytest.fixture(scope="module")
def openmcx_tree() -> Path:
    given = os.environ.get("OPENMCX_SRC")
    if not given:
        pytest.skip("OPENMCX_SRC is not set: no local OpenMCx tree to take its examples from")
    tree = Path(given)
    missing = [
        p for p in ("examples", "fmus/gain.fmu", "fmus/vectorSum.fmu") if not (tree / p).exists()
    ]
    if missing:
        pytest.skip(f"OPENMCX_SRC={tree} lacks {', '.join(missing)} (build OpenMCx first)")
    return tree


@pytest.mark.parametrize("example", EXAMPLES)
def test_example_writes_openmcx_files(
    coupler: Coupler, tmp_path: Path, openmcx_tree: Path, example: str
) -> None:
    folder = openmcx_tree / "examples" / example
    outcome = coupler(
        "run", folder / "model.ssd", "--out", tmp_path, "--no-progress", "--openmcx-results"
    )
    assert outcome.code == 0, outcome.err
    references = sorted(p.name for p in (folder / "reference").glob("*.csv"))
    assert sorted(p.name for p in tmp_path.glob("*_*.csv")) == references
    problems: list[str] = []
    worst = 0.0
    for name in references:
        found, largest = differences(folder / "reference" / name, tmp_path / name)
        problems += found
        worst = max(worst, largest)
    print(f"{example}: {len(references)} files, largest relative difference {worst:.2g}")
    assert not problems, "\n".join(problems[:20])


@pytest.mark.parametrize("example", EXAMPLES)
def test_example_results_csv(
    coupler: Coupler, tmp_path: Path, openmcx_tree: Path, example: str
) -> None:
    """Plain ``coupler run``: results.csv holds each reference output at each reference time
    (the column of the participant's channel the SSD connector names)."""
    folder = openmcx_tree / "examples" / example
    outcome = coupler("run", folder / "model.ssd", "--out", tmp_path, "--no-progress")
    assert outcome.code == 0, outcome.err
    scenario = load_ssp(folder / "model.ssd")
    rows = {round(float(r["time"]), 9): r for r in coupler.results(tmp_path)}
    worst, problems = 0.0, []
    for reference in sorted((folder / "reference").glob("*_res.csv")):
        component = scenario.component(reference.stem.removesuffix("_res"))
        assert component is not None
        head, _, lines = table(reference)
        for j, name in enumerate(head[1:], 1):
            connector = component.connector(name)
            assert connector is not None
            values = [float(line[j]) for line in lines]
            scale = max(abs(v) for v in values) or 1.0
            for line, want in zip(lines, values, strict=True):
                got = float(rows[round(float(line[0]), 9)][f"{component.name}.{connector.channel}"])
                error = abs(got - want) / scale
                worst = max(worst, error)
                if not error <= TOLERANCE:
                    problems.append(f"{component.name}.{name} at t={line[0]}: {got} != {want}")
    print(f"{example}: results.csv, largest relative difference {worst:.2g}")
    assert not problems, "\n".join(problems[:20])
