"""Scenario tests: real FMUs and real gRPC participants under ``coupler run``.

Each test opens with its topology and asserts the recorded step trace (results.csv). Expected
values are computed by hand from the models' equations (fmus/common/*.h, coupler.examples.gain).
"""

from __future__ import annotations

import os
import shutil
import zipfile
from pathlib import Path

import pytest

from coupler.server import ParticipantServer

from .support import DATA, REPO, Coupler

pytestmark = pytest.mark.usefixtures("fmus")


def test_chain_jacobi(coupler: Coupler, tmp_path: Path) -> None:
    """Jacobi: every member steps on the outputs of the previous communication point.

        Source --ramp--> Feed (x2) --real_out--> Integ        h = 0.5, 0 .. 2 s
        Source --counter--> Feed.int_in

    Each hop adds one step of delay: real_out(t_k) = 2 ramp(t_{k-1});
    x(t_{k+1}) = x(t_k) + h real_out(t_k).
    """
    outcome = coupler("run", DATA / "chain.ssd", "--out", tmp_path, "--algorithm", "jacobi")
    assert outcome.code == 0, outcome.err
    assert coupler.column(tmp_path, "time") == [0.0, 0.5, 1.0, 1.5, 2.0]
    assert coupler.column(tmp_path, "Source.ramp") == [0.0, 0.5, 1.0, 1.5, 2.0]
    assert coupler.column(tmp_path, "Source.counter") == [0, 1, 2, 3, 4]
    assert coupler.column(tmp_path, "Feed.real_out") == [0.0, 0.0, 1.0, 2.0, 3.0]
    assert coupler.column(tmp_path, "Feed.int_out") == [0, 0, 1, 2, 3]
    assert coupler.column(tmp_path, "Integ.x") == [0.0, 0.0, 0.0, 0.5, 1.5]
    summary = coupler.summary(tmp_path)
    assert (summary["status"], summary["algorithm"], summary["steps"]) == ("completed", "jacobi", 4)
    assert {c["name"]: c["unit"] for c in summary["columns"]}["Integ.x"] == "m"


def test_chain_gauss_seidel(coupler: Coupler, tmp_path: Path) -> None:
    """Gauss-Seidel: members step in topological order, each seeing its predecessors' new
    outputs.

        Source --ramp--> Feed (x2) --real_out--> Integ        h = 0.5, 0 .. 2 s

    real_out(t_k) = 2 ramp(t_k); x(t_{k+1}) = x(t_k) + h real_out(t_{k+1}).
    """
    # chain.ssd's OpenMCx task says stepType="sequential": Gauss-Seidel without --algorithm
    outcome = coupler("run", DATA / "chain.ssd", "--out", tmp_path)
    assert outcome.code == 0, outcome.err
    assert coupler.column(tmp_path, "Feed.real_out") == [0.0, 1.0, 2.0, 3.0, 4.0]
    assert coupler.column(tmp_path, "Feed.int_out") == [0, 1, 2, 3, 4]
    assert coupler.column(tmp_path, "Integ.x") == [0.0, 0.5, 1.5, 3.0, 5.0]
    assert coupler.summary(tmp_path)["algorithm"] == "gauss-seidel"


@pytest.mark.parametrize(
    ("algorithm", "x"),
    [
        # Jacobi: Source's outputs of t_{k+2} become visible at t_{k+2}; Integ's u is held
        ("jacobi", [0.0, 0.0, 0.0, 0.5, 1.0]),
        # Gauss-Seidel: the same visibility; Integ, after Source, sees them in the step
        # ending at t_{k+2}, so u over [t1, t2] is ramp(t2) = 1 and over [t3, t4] ramp(t4) = 2
        ("gauss-seidel", [0.0, 0.0, 0.5, 1.0, 2.0]),
    ],
)
def test_step_multiples(coupler: Coupler, tmp_path: Path, algorithm: str, x: list[float]) -> None:
    """Source steps every second base step (deltaTime = 2 h), Integ every base step.

        Source (deltaTime 1.0) --ramp--> Integ (h 0.5)        0 .. 2 s

    The recorded ramp changes only at t_0, t_2, t_4: a row never shows a value from a later
    time.
    """
    outcome = coupler("run", DATA / "multiples.ssd", "--out", tmp_path, "--algorithm", algorithm)
    assert outcome.code == 0, outcome.err
    assert coupler.column(tmp_path, "Source.ramp") == [0.0, 0.0, 1.0, 1.0, 2.0]
    assert coupler.column(tmp_path, "Source.counter") == [0, 0, 1, 1, 2]
    assert coupler.column(tmp_path, "Integ.x") == x
    participants = coupler.summary(tmp_path)["participants"]
    assert (participants["Source"]["multiple"], participants["Source"]["steps"]) == (2, 2)
    assert (participants["Integ"]["multiple"], participants["Integ"]["steps"]) == (1, 4)


def test_step_multiple_must_divide_the_run(coupler: Coupler, tmp_path: Path) -> None:
    """Source's deltaTime 1.0 s does not fit into 0 .. 2.5 s: refused before anything runs."""
    outcome = coupler("validate", DATA / "multiples.ssd", "--stop-time", "2.5")
    assert outcome.code == 1
    assert "component 'Source' deltaTime 1 s does not divide the run" in outcome.err


def _ssp(tmp_path: Path, ssd: Path, fmus: list[str]) -> Path:
    """An .ssp archive: the SSD as SystemStructure.ssd, the FMUs under resources/."""
    archive = tmp_path / f"{ssd.stem}.ssp"
    text = ssd.read_text().replace("${COUPLER_FMU_DIR}/", "resources/")
    built = Path(os.environ["COUPLER_FMU_DIR"])
    with zipfile.ZipFile(archive, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("SystemStructure.ssd", text)
        for name in fmus:
            zf.write(built / f"{name}.fmu", f"resources/{name}.fmu")
    return archive


def test_fmus_and_grpc_participant_every_type(
    coupler: Coupler, tmp_path: Path, gain_server: ParticipantServer
) -> None:
    """An .ssp archive with three FMUs and the example gain participant over gRPC.

        Source (FMI 2) --ramp, counter--> Gain (gRPC, gain 3, offset 10, label "hi")
        Gain --y, count, inverted, echo, blob_out--> Feed (FMI 3)
        Feed --real_out, int_out, bool_out, string_out--> Feed2 (FMI 2)

    Jacobi, h = 0.5, 0 .. 1.5 s: each hop delays by one step. The gRPC address comes from
    ${GAIN_PORT}; Gain.blob (Binary) is set with --param.
    """
    archive = _ssp(tmp_path, DATA / "mixed.ssd", ["Source2", "Feedthrough3", "Feedthrough2"])
    out = tmp_path / "out"
    outcome = coupler("run", archive, "--out", out, "--param", "Gain.blob=00010203ff")
    assert outcome.code == 0, outcome.err
    assert "completed: 3 steps to t=1.5 s" in outcome.out
    rows = coupler.results(out)
    column = {name: [row[name] for row in rows] for name in rows[0]}
    assert column["Gain.y"] == ["0.0", "0.0", "1.5", "3.0"]
    assert column["Gain.x"] == ["0.0", "0.0", "0.25", "0.75"]
    assert column["Gain.count"] == ["10", "10", "11", "12"]
    assert column["Gain.echo"] == ["hi"] * 4
    assert column["Feed.real_out"] == ["0.0", "0.0", "0.0", "3.0"]
    assert column["Feed.int_out"] == ["0", "10", "10", "11"]
    assert column["Feed.bool_out"] == ["1", "0", "0", "0"]
    assert column["Feed.string_out"] == ["", "hi", "hi", "hi"]
    assert column["Feed2.real_out"] == ["0.0", "0.0", "0.0", "0.0"]
    assert column["Feed2.int_out"] == ["0", "0", "10", "10"]
    assert column["Feed2.bool_out"] == ["1", "0", "1", "1"]
    assert column["Feed2.string_out"] == ["", "", "hi", "hi"]
    assert column["Feed.binary_out"][0] == ""
    assert column["Feed.binary_out"][1:] == ["ff03020100"] * 3  # Gain reversed the bytes
    summary = coupler.summary(out)
    assert summary["implementations"]["Gain"] == "coupler.examples.gain"
    assert summary["participants"]["Gain"]["steps"] == 3


def test_results_are_deterministic(
    coupler: Coupler, tmp_path: Path, gain_server: ParticipantServer
) -> None:
    """The same SSP and participants give a byte-identical results.csv.

    Source (FMI 2) --> Gain (gRPC) --> Feed (FMI 3) --> Feed2 (FMI 2), run twice.
    """
    for run in ("a", "b"):
        assert coupler("run", DATA / "mixed.ssd", "--out", tmp_path / run).code == 0
    first = (tmp_path / "a" / "results.csv").read_bytes()
    assert first == (tmp_path / "b" / "results.csv").read_bytes()
    assert first.count(b"\n") == 5


def test_shipped_example_runs_bit_exact(
    coupler: Coupler, tmp_path: Path, gain_server: ParticipantServer, fmus: dict[str, Path]
) -> None:
    """examples/ramp-gain as shipped, against FMUs where its relative sources point.

        Source (FMI 2, slope 0.5) --ramp--> Gain (gRPC, gain 4) --y--> Integrator (FMI 2)

    Jacobi, h = 0.1, 0 .. 10 s; compared bit for bit with the same arithmetic in Python. The
    grid is t_k = k/10, the decimals as written (0.3, not 3 * 0.1); each step is
    doStep(t_k, h) with h exactly 0.1, so the FMUs' own clock after a step is t_k + h (which
    need not equal t_{k+1} to the last bit).
    """
    example = tmp_path / "examples" / "ramp-gain"
    example.mkdir(parents=True)
    shutil.copy(REPO / "examples" / "ramp-gain" / "SystemStructure.ssd", example)
    (tmp_path / "build" / "fmus").mkdir(parents=True)
    for name in ("Source2", "Integrator2"):
        shutil.copy(fmus[name], tmp_path / "build" / "fmus")
    out = tmp_path / "out"
    outcome = coupler("run", example / "SystemStructure.ssd", "--out", out)
    assert outcome.code == 0, outcome.err
    times = [k / 10 for k in range(101)]
    clock = [0.0] + [t + 0.1 for t in times[:-1]]  # the FMU's time after doStep(t_k, h)
    ramp = [0.5 * t + 0.0 for t in clock]
    y = [0.0] + [4.0 * r for r in ramp[:-1]]
    x = [0.0]
    for k in range(100):
        x.append(x[-1] + y[k] * 0.1)
    assert coupler.column(out, "time") == times
    assert coupler.column(out, "Source.ramp") == ramp
    assert coupler.column(out, "Gain.y") == y
    assert coupler.column(out, "Integrator.x") == x
