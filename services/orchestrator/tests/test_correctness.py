"""Results that are right or refused: units across connections, exact step sizes, participants
ending a run, complete outputs, single FMUs, grids that cannot run.

Real gRPC participants (ParticipantServer on port 0) and FMUs built from fmus/; every run goes
through the ``coupler`` CLI.
"""

from __future__ import annotations

import csv
import io
import json
import os
import shutil
import subprocess
import sys
import time
import zipfile
from collections.abc import Mapping
from fractions import Fraction
from pathlib import Path
from typing import Any

import fmpy
import pytest
from hypothesis import given
from hypothesis import strategies as st

from coupler.channels import Causality, Channel, Description, RunSetup, Value, ValueType
from coupler.messages import encode_message
from coupler.participant import EndRun, Participant, Values
from coupler.testing import Annotation, Component, SystemStructure, fmu, remote
from coupler_orchestrator.observer import Column
from coupler_orchestrator.outputs.csv import csv_field, formatter, row_formatter
from coupler_railway.messages import TRAIN_STATE

from .support import Coupler, project_fmu, serving
from .support.rows import RESULT_ROWS

pytestmark = pytest.mark.usefixtures("fmus")


def served_at(name: str, port: int, **options: Any) -> Component:
    """A participant served on 127.0.0.1 at ``port``; its connectors without type or unit:
    those come from the participant."""
    return remote(name, f"grpc://127.0.0.1:{port}", **options)


def write(
    tmp_path: Path,
    components: list[Component],
    connections: list[tuple[str, str]],
    start: float = 0.0,
    stop: float = 1.0,
) -> Path:
    system = SystemStructure("T", components, connections, start_time=start, stop_time=stop)
    return system.write(tmp_path / "t.ssd")


def speedo_to_integrator(tmp_path: Path, port: int) -> Path:
    """Speedo (gRPC at ``port``) --y--> Integ.u (Integrator2 FMU)."""
    speedo = served_at("Speedo", port, outputs=["y"])
    integ = project_fmu("Integ", "Integrator2", inputs=["u"])
    return write(tmp_path, [speedo, integ], [("Speedo.y", "Integ.u")])


class Source(Participant):
    """One output ``y`` with a unit, constant ``value``; records what it is asked to do."""

    def __init__(self, unit: str, value: float = 36.0, name: str = "Speedo") -> None:
        self.unit, self.value, self.name = unit, value, name
        self.steps: list[tuple[float, float]] = []
        self.setup: RunSetup | None = None

    async def describe(self) -> Description:
        return Description(
            name=self.name,
            channels=(
                Channel(name="y", causality=Causality.OUTPUT, type=ValueType.REAL, unit=self.unit),
            ),
        )

    async def initialize(self, setup: RunSetup) -> Values:
        self.setup, self.steps = setup, []
        return {"y": self.value}

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        self.steps.append((time, step))
        return await self.answer(time, step)

    async def answer(self, time: float, step: float) -> Values:
        return {"y": self.value}

    async def terminate(self, reason: str = "") -> None:
        pass


def test_kmh_from_a_participant_arrive_as_ms_at_an_fmu(coupler: Coupler, tmp_path: Path) -> None:
    """Units are compared across the connection although the SSD declares none.

        Speedo (gRPC, y = 36 km/h) --y--> Integ.u (Integrator2 FMU, m/s): x' = u

    36 km/h is 10 m/s: x grows by 10 * h per step (Jacobi: from the first step on, u is the
    initial output).
    """
    with serving(Source("km/h")) as server:
        path = speedo_to_integrator(tmp_path, server.port)
        outcome = coupler("run", path, "--step", "0.25", "--out", tmp_path / "o")
    assert outcome.code == 0, outcome.err
    assert coupler.column(tmp_path / "o", "Integ.x") == [0.0, 2.5, 5.0, 7.5, 10.0]


def test_m_to_s_is_refused_naming_both_ends(coupler: Coupler, tmp_path: Path) -> None:
    with serving(Source("m")) as server:
        path = speedo_to_integrator(tmp_path, server.port)
        outcome = coupler("validate", path, "--step", "0.25")
    assert outcome.code == 1
    assert (
        "t.ssd line 20: connection Speedo.y -> Integ.u: 'Speedo.y' is in m but 'Integ.u' is in "
        "m/s, and m and m s-1 are different dimensions"
    ) in outcome.err


def test_a_unit_nobody_understands_is_warned_not_ignored(coupler: Coupler, tmp_path: Path) -> None:
    with serving(Source("parsecs per fortnite")) as server:
        path = speedo_to_integrator(tmp_path, server.port)
        validated = coupler("validate", path, "--step", "0.25")
        ran = coupler("run", path, "--step", "0.25", "--out", tmp_path / "o")
    message = "unit 'parsecs per fortnite' is not understood"
    assert validated.code == 0 and message in validated.out
    assert ran.code == 0
    assert any(message in w for w in coupler.summary(tmp_path / "o")["warnings"])


def test_step_sizes_arrive_exactly_as_configured(coupler: Coupler, tmp_path: Path) -> None:
    """h = 0.1 from t_0 = 0.2: every step is 0.1 (not t_{k+1} - t_k, which would arrive as
    0.09999999999999998, 0.10000000000000003, ...), times are t_0 + k h; a component with
    deltaTime 0.3 gets 0.3 exactly (not 3 * 0.1 = 0.30000000000000004)."""
    every = Source("", name="Every")
    third = Source("", name="Third")
    slow = Annotation("com.avl.model.connect.ssp.component", "Component", {"deltaTime": "0.3"})
    with serving(every) as a, serving(third) as b:
        path = write(
            tmp_path,
            [served_at("Every", a.port), served_at("Third", b.port, annotations=[slow])],
            [],
            0.2,
            2.0,
        )
        outcome = coupler("run", path, "--step", "0.1", "--out", tmp_path / "o")
    assert outcome.code == 0, outcome.err
    assert every.setup is not None and every.setup.step_size == 0.1
    assert every.steps == [((2 + k) / 10, 0.1) for k in range(18)]
    assert third.setup is not None and third.setup.step_size == 0.3
    assert third.steps == [((2 + k) / 10, 0.3) for k in range(0, 18, 3)]
    assert all(step == 0.1 for _, step in every.steps)  # bit for bit, not approximately


@pytest.mark.parametrize(("start", "step", "stop"), [("0", "0.1", "100"), ("0.25", "0.1", "3.35")])
def test_the_time_column_is_the_grid_the_user_wrote(
    coupler: Coupler,
    tmp_path: Path,
    fmus: dict[str, Path],
    fmu_path: str,
    start: str,
    step: str,
    stop: str,
) -> None:
    """A 0.1 s grid writes 0.3, 0.6, ... — the nearest double to the exact decimal t_0 + k h,
    not the sum or product of doubles (0.30000000000000004): a user filtering ``time == 0.3``
    or joining with another tool's 0.1 s grid finds every row. The FMU is stepped from those
    very times (FMI's currentCommunicationPoint), in C and in Python alike."""
    out = tmp_path / "o"
    outcome = coupler(
        "run", fmus["Source2"], "--out", out,
        "--start-time", start, "--step", step, "--stop-time", stop,
    )  # fmt: skip
    assert outcome.code == 0, outcome.err
    times = [row["time"] for row in coupler.results(out)]
    t0, h = Fraction(start), Fraction(step)
    expected = [repr(float(t0 + k * h)) for k in range(len(times))]
    assert times == expected
    assert float(times[-1]) == float(stop)
    assert all(len(t.partition(".")[2]) <= 2 for t in times)  # 0.3, 12.7, 3.35: never ...0004


class Tank(Source):
    """Asks to end the run once it is empty (t >= 0.75)."""

    async def answer(self, time: float, step: float) -> Values:
        if time + step >= 0.75:
            raise EndRun("the tank is empty", {"y": -1.0})
        return {"y": self.value}


def test_a_grpc_participant_ends_the_run(coupler: Coupler, tmp_path: Path) -> None:
    """Tank (gRPC) --y--> Integ.u: Tank asks to stop at t = 0.75; the run ends there."""
    with serving(Tank("m/s", 1.0, name="Tank")) as server:
        path = write(
            tmp_path,
            [
                served_at("Tank", server.port, outputs=["y"]),
                project_fmu("Integ", "Integrator2", inputs=["u"]),
            ],
            [("Tank.y", "Integ.u")],
        )
        outcome = coupler("run", path, "--step", "0.25", "--out", tmp_path / "o")
    assert outcome.code == 0, outcome.err
    assert "terminated early: Tank asked to end the run at t=0.75 s: the tank is empty" in (
        outcome.out
    )
    summary = coupler.summary(tmp_path / "o")
    assert (summary["status"], summary["end_time"], summary["steps"]) == ("terminated", 0.75, 3)
    assert coupler.column(tmp_path / "o", "time") == [0.0, 0.25, 0.5, 0.75]
    assert coupler.column(tmp_path / "o", "Tank.y")[-1] == -1.0  # the last answer is recorded


class Forgetful(Source):
    """Leaves its output out of the answer to the third step."""

    async def answer(self, time: float, step: float) -> Values:
        return {} if len(self.steps) == 3 else {"y": self.value}


def test_an_output_missing_from_an_answer_fails_the_run_naming_it(
    coupler: Coupler, tmp_path: Path
) -> None:
    with serving(Forgetful("", name="Forgetful")) as server:
        path = write(tmp_path, [served_at("Forgetful", server.port)], [])
        outcome = coupler("run", path, "--step", "0.25", "--out", tmp_path / "o")
    assert outcome.code == 1
    summary = coupler.summary(tmp_path / "o")
    assert summary["status"] == "failed"
    assert (
        "Forgetful.DoStep: answered DoStep for t=0.75 s without its described outputs y"
        in summary["reason"]
    )
    assert coupler.column(tmp_path / "o", "time") == [0.0, 0.25, 0.5]  # completed rows kept


def with_experiment(fmu_path: Path, target: Path, experiment: str) -> Path:
    """A copy of an FMU whose modelDescription carries ``experiment`` (a DefaultExperiment)."""
    with zipfile.ZipFile(fmu_path) as source, zipfile.ZipFile(target, "w") as copy:
        for item in source.infolist():
            data = source.read(item)
            if item.filename == "modelDescription.xml":
                data = data.replace(b"<ModelVariables>", experiment.encode() + b"<ModelVariables>")
            copy.writestr(item, data)
    return target


def test_a_single_fmu_runs_like_fmpy(
    coupler: Coupler, tmp_path: Path, fmus: dict[str, Path]
) -> None:
    """``coupler run X.fmu``: its DefaultExperiment, every output, bit for bit as
    ``fmpy.simulate_fmu`` (a dyadic step, so FMPy's step t_{k+1} - t_k is exactly Coupler's h);
    then the experiment overridden from the command line, with parameters by their bare names."""
    fmu_path = with_experiment(
        fmus["Integrator2"],
        tmp_path / "Integrator2.fmu",
        '<DefaultExperiment startTime="0.5" stopTime="2.5" stepSize="0.125"/>',
    )
    outcome = coupler("run", fmu_path, "--out", tmp_path / "a", "--param", "u=-0.5")
    assert outcome.code == 0, outcome.err
    reference = fmpy.simulate_fmu(str(fmu_path), start_values={"u": -0.5}, fmi_type="CoSimulation")
    assert coupler.column(tmp_path / "a", "time") == [float(r["time"]) for r in reference]
    assert coupler.column(tmp_path / "a", "Integrator.x") == [float(r["x"]) for r in reference]
    assert len(reference) == 17
    outcome = coupler(
        "run", fmu_path, "--out", tmp_path / "b", "--start-time", "0", "--stop-time", "4",
        "--step", "0.25", "--param", "x0=0.75", "--param", "Integrator.u=1.5",
    )  # fmt: skip
    assert outcome.code == 0, outcome.err
    reference = fmpy.simulate_fmu(
        str(fmu_path),
        start_time=0.0,
        stop_time=4.0,
        output_interval=0.25,
        start_values={"x0": 0.75, "u": 1.5},
        fmi_type="CoSimulation",
    )
    assert coupler.column(tmp_path / "b", "Integrator.x") == [float(r["x"]) for r in reference]


def test_a_single_fmu_without_an_experiment_uses_fmpys_defaults(
    coupler: Coupler, tmp_path: Path, fmus: dict[str, Path]
) -> None:
    """0 .. 1 s in steps of 0.002 (FMPy's rule); every output recorded."""
    outcome = coupler("run", fmus["Source2"], "--out", tmp_path / "o")
    assert outcome.code == 0, outcome.err
    rows = coupler.results(tmp_path / "o")
    assert list(rows[0]) == ["time", "Source.ramp", "Source.sine", "Source.counter"]
    assert len(rows) == 501 and float(rows[-1]["time"]) == 1.0
    assert coupler.summary(tmp_path / "o")["step_size"] == 0.002


def test_an_unpacked_ssp_folder_runs_like_its_archive(
    coupler: Coupler, tmp_path: Path, fmus: dict[str, Path]
) -> None:
    ssd = (Path(__file__).parent / "data" / "chain.ssd").read_text()
    ssd = ssd.replace("${COUPLER_FMU_DIR}", "resources")
    folder = tmp_path / "unpacked"
    (folder / "resources").mkdir(parents=True)
    (folder / "SystemStructure.ssd").write_text(ssd)
    for name in ("Source2", "Feedthrough3", "Integrator2"):
        shutil.copy(fmus[name], folder / "resources")
    archive = tmp_path / "chain.ssp"
    with zipfile.ZipFile(archive, "w") as zf:
        for item in folder.rglob("*"):
            zf.write(item, item.relative_to(folder).as_posix())
    assert coupler("run", folder, "--out", tmp_path / "dir").code == 0
    assert coupler("run", archive, "--out", tmp_path / "ssp").code == 0
    assert (tmp_path / "dir" / "results.csv").read_bytes() == (
        tmp_path / "ssp" / "results.csv"
    ).read_bytes()


def test_gauss_seidel_refuses_a_component_feeding_itself(coupler: Coupler, tmp_path: Path) -> None:
    path = write(
        tmp_path,
        [project_fmu("Feed", "Feedthrough2", inputs=["real_in"], outputs=["real_out"])],
        [("Feed.real_out", "Feed.real_in")],
    )
    refused = coupler("validate", path, "--step", "0.5", "--algorithm", "gauss-seidel")
    assert refused.code == 1
    assert "component 'Feed' feeds itself (Feed.real_out -> Feed.real_in)" in refused.err
    assert coupler("validate", path, "--step", "0.5", "--algorithm", "jacobi").code == 0


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--stop-time", "inf"], "stop time inf (--stop-time) is not a finite number"),
        (["--stop-time", "nan"], "stop time nan (--stop-time) is not a finite number"),
        (["--step", "inf"], "step size inf (--step) is not a finite number"),
        (["--start-time=-inf"], "start time -inf (--start-time) is not a finite number"),
        (["--step", "1e-300"], "more than 1e+10; check the step's unit"),
        (["--step", "0"], "step size must be positive, got 0 s (--step)"),
        (["--step", "0.3"], "is not start 0 s plus a whole number of steps of 0.3 s"),
    ],
)
def test_grids_that_cannot_run_are_refused(
    coupler: Coupler, tmp_path: Path, options: list[str], message: str
) -> None:
    path = write(tmp_path, [project_fmu("Feed", "Feedthrough2")], [])
    opts = options if "--step" in options else [*options, "--step", "0.5"]
    outcome = coupler("run", path, "--out", tmp_path / "o", *opts)
    assert outcome.code == 1
    assert message in outcome.err
    assert "Traceback" not in outcome.err
    assert not (tmp_path / "o" / "results.csv").exists()


def test_an_infinite_openmcx_delta_time_is_refused(coupler: Coupler, tmp_path: Path) -> None:
    path = write(tmp_path, [project_fmu("Feed", "Feedthrough2")], [])
    text = path.read_text().replace(
        '<ssd:DefaultExperiment startTime="0.0" stopTime="1.0"/>',
        '<ssd:DefaultExperiment startTime="0" stopTime="1"><ssd:Annotations>'
        '<ssc:Annotation type="com.avl.model.connect.ssp.task">'
        '<t:Task xmlns:t="com.avl.model.connect.ssp.task" stepType="parallel_single_thread" '
        'deltaTime="INF"/></ssc:Annotation></ssd:Annotations></ssd:DefaultExperiment>',
    )
    path.write_text(text)
    outcome = coupler("validate", path)
    assert outcome.code == 1
    assert "step size inf (deltaTime in t.ssd) is not a finite number" in outcome.err


def test_output_interval_and_variables_select_what_is_recorded(
    coupler: Coupler, tmp_path: Path
) -> None:
    """``--output-variables A,B`` before the scenario takes the list, not the scenario."""
    path = Path(__file__).parent / "data" / "chain.ssd"
    outcome = coupler(
        "run", "--output-variables", "Integ.*,Source.ramp", path,
        "--out", tmp_path / "o", "--output-interval", "1.0",
    )  # fmt: skip
    assert outcome.code == 0, outcome.err
    rows = coupler.results(tmp_path / "o")
    assert list(rows[0]) == ["time", "Source.ramp", "Integ.x"]
    assert [row["time"] for row in rows] == ["0.0", "1.0", "2.0"]
    refused = coupler(
        "run", path, "--out", tmp_path / "p", "--output-interval", "0.75",
        "--output-variables", "Nope.*",
    )  # fmt: skip
    assert refused.code == 1
    assert "--output-interval 0.75 s is not a whole multiple of the step 0.5 s" in refused.err
    assert "--output-variables Nope.*: matches no output" in refused.err


class Train(Participant):
    """A binary output carrying a registered message (coupler.v1.TrainState)."""

    async def describe(self) -> Description:
        return Description(
            name="Train",
            channels=(
                Channel(
                    name="state",
                    causality=Causality.OUTPUT,
                    type=ValueType.BINARY,
                    message_type=TRAIN_STATE,
                ),
            ),
        )

    async def initialize(self, setup: RunSetup) -> Values:
        return {"state": b""}

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        fields = {"time_s": time + step, "speed_mps": 2.0 * (time + step), "distance_m": 7.0}
        return {"state": encode_message(TRAIN_STATE, fields)}

    async def terminate(self, reason: str = "") -> None:
        pass


def test_a_train_state_column_reads_as_json(coupler: Coupler, tmp_path: Path) -> None:
    """``coupler run`` as the user runs it — a process that never imported coupler_railway —
    finds coupler.v1.TrainState through the installed package's ``coupler.messages`` entry
    point and writes the column as JSON, not hex."""
    with serving(Train()) as server:
        path = write(tmp_path, [served_at("Train", server.port)], [])
        outcome = coupler.process("run", path, "--step", "0.5", "--out", tmp_path / "o")
    assert outcome.code == 0, outcome.err
    cells = [row["Train.state"] for row in coupler.results(tmp_path / "o")]
    assert cells[0] == ""  # no state yet
    last = json.loads(cells[-1])
    assert (last["time_s"], last["speed_mps"], last["distance_m"]) == (1.0, 2.0, 7.0)
    columns = {c["name"]: c for c in coupler.summary(tmp_path / "o")["columns"]}
    assert columns["Train.state"]["message_type"] == "coupler.v1.TrainState"


def test_an_archive_and_its_fmus_share_one_unpack_budget(
    coupler: Coupler, tmp_path: Path, fmus: dict[str, Path]
) -> None:
    """1.5 MB of the .ssp's own files and an FMU that unpacks 1 MB more: fine with 4 MB,
    refused with 2 MB although each part alone would fit."""
    padded = tmp_path / "Source2.fmu"
    with zipfile.ZipFile(fmus["Source2"]) as source, zipfile.ZipFile(padded, "w") as copy:
        for item in source.infolist():
            copy.writestr(item, source.read(item))
        copy.writestr("resources/padding.bin", bytes(1024 * 1024), zipfile.ZIP_DEFLATED)
    ssd = write(tmp_path, [fmu("Source", "resources/Source2.fmu")], [])
    archive = tmp_path / "padded.ssp"
    with zipfile.ZipFile(archive, "w") as zf:
        zf.write(ssd, "SystemStructure.ssd")
        zf.write(padded, "resources/Source2.fmu")
        zf.writestr("resources/data.bin", os.urandom(1536 * 1024))  # does not compress
    ran = coupler("run", archive, "--out", tmp_path / "ok", "--step", "0.5", "--unpack-limit", "4")
    assert ran.code == 0, ran.err
    refused = coupler(
        "run", archive, "--out", tmp_path / "no", "--step", "0.5", "--unpack-limit", "2"
    )
    assert refused.code == 1
    assert "exceed the 2097152 bytes a scenario may unpack (archive and FMUs together)" in (
        refused.err
    )
    assert "component 'Source'" in refused.err


def padded_fmu(fmu: Path, target: Path, megabytes: int) -> Path:
    """``fmu`` with ``megabytes`` MB of zeros in resources/: it unpacks that much more, from a
    file of a few kB."""
    with zipfile.ZipFile(fmu) as source, zipfile.ZipFile(target, "w") as copy:
        for item in source.infolist():
            copy.writestr(item, source.read(item))
        copy.writestr("resources/padding.bin", bytes(megabytes << 20), zipfile.ZIP_DEFLATED)
    return target


@pytest.mark.parametrize("isolated", [False, True], ids=["in-process", "isolated"])
def test_isolated_fmus_share_the_run_s_one_unpack_budget(
    tmp_path: Path, fmus: dict[str, Path], isolated: bool
) -> None:
    """Three FMUs unpacking 24 MB each against --unpack-limit 64: refused before any of them
    starts, naming the budget, in process and isolated alike (each isolated host used to get
    a 2 GiB budget of its own: the run completed)."""
    components: list[Component] = []
    for i in (1, 2, 3):
        padded_fmu(fmus["Source2"], tmp_path / f"Big{i}.fmu", 24)
        components.append(fmu(f"Big{i}", f"Big{i}.fmu"))
    ssd = write(tmp_path, components, [])
    command = [
        sys.executable, "-m", "coupler_orchestrator", "run", str(ssd), "--out",
        str(tmp_path / "o"), "--step", "0.5", "--unpack-limit", "64",
        *(["--isolate-fmus"] if isolated else []),
    ]  # fmt: skip
    started = time.monotonic()
    ran = subprocess.run(command, capture_output=True, text=True, timeout=120)
    took = time.monotonic() - started
    assert ran.returncode == 1, ran.stderr
    assert "exceed the 67108864 bytes a scenario may unpack (archive and FMUs together)" in (
        ran.stderr
    )
    assert "crashed" not in ran.stderr and "Traceback" not in ran.stderr
    assert not (tmp_path / "o" / "results.csv").exists()
    assert took < 20, took  # not the host's 30 s start-up timeout


def test_results_as_parquet_equal_the_csv(coupler: Coupler, tmp_path: Path) -> None:
    """--parquet: the same rows, typed columns; selection and decimation apply alike."""
    pq = pytest.importorskip("pyarrow.parquet", reason="pyarrow is not installed")
    path = Path(__file__).parent / "data" / "chain.ssd"
    outcome = coupler(
        "run", path, "--out", tmp_path, "--parquet", "--output-interval", "1.0",
        "--output-variables", "Source.*", "--output-variables", "Integ.x",
    )  # fmt: skip
    assert outcome.code == 0, outcome.err
    table = pq.read_table(tmp_path / "results.parquet")
    rows = coupler.results(tmp_path)
    assert table.column_names == list(rows[0])
    assert table.schema.field("Source.counter").type == "int64"
    assert table.column("time").to_pylist() == [float(r["time"]) for r in rows]
    assert table.column("Integ.x").to_pylist() == [float(r["Integ.x"]) for r in rows]
    assert table.column("Source.counter").to_pylist() == [int(r["Source.counter"]) for r in rows]


@given(st.lists(st.text(), min_size=1, max_size=5))
def test_csv_fields_are_written_exactly_as_the_csv_module_writes_them(texts: list[str]) -> None:
    """results.csv rows are joined by hand (faster); every byte as csv.writer would write it."""
    written = io.StringIO()
    csv.writer(written, lineterminator="\n").writerow(["0.5", *texts])
    assert ",".join(["0.5", *(csv_field(t) for t in texts)]) + "\n" == written.getvalue()


@given(RESULT_ROWS)
def test_a_results_row_is_its_cells_as_each_columns_formatter_writes_them(case: Any) -> None:
    """results.csv's rows come from one %-format made per run; every byte as the columns'
    formatters write the cells one by one, for any selection of columns."""
    types, row, chosen, time = case
    columns = [Column(name=f"C.v{i}", unit="", type=t) for i, t in enumerate(types)]
    picked = sorted(chosen)
    cells = [repr(time), *(formatter(columns[i])(row[i]) for i in picked)]
    assert row_formatter(columns, picked)(time, row) == ",".join(cells) + "\n"
