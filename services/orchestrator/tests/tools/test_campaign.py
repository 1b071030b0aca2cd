"""``coupler campaign`` with real processes: the ramp-gain example under a 3 x 3 grid, here
(parallel runs) and on a Dask LocalCluster of worker processes; a run that fails is a row and
the others complete; a second campaign run skips what completed; a pool of running
participants instead of per-run services; campaign files that cannot run are refused.

    campaign --per run--> fleet (gain participant on a free port) + `coupler run` process
        |                  Source (FMU) -> Gain (gRPC) -> Integrator (FMU)
        v
    out/campaign.csv, out/runs/<n>-<key>/{results.csv, summary.json, variant.json, run.log}
"""

from __future__ import annotations

import asyncio
import contextlib
import csv
import json
import resource
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from coupler.testing import free_port, process_group, wait_until_serving
from coupler_orchestrator.cli.main import main
from coupler_orchestrator.tools.campaign import (
    CampaignError,
    CampaignSpec,
    Output,
    reduce,
    run_campaign,
)
from coupler_orchestrator.tools.campaign.model import RunReport
from coupler_orchestrator.tools.campaign.table import write_table
from coupler_orchestrator.tools.campaign.worker import report_value

from ..support import REPO

EXAMPLE = REPO / "examples" / "ramp-gain"

GRID = """
[grid]
"Gain.gain" = [1.0, 2.0, 3.0]
"Source.slope" = [0.5, 1.0, 2.0]

[outputs]
y_max = "max(Gain.y)"
x_final = "Integrator.x"
y_changes = "count_changes(Gain.y)"

[checks]
y_bounded = "y_max <= 2 * x_final + 20"
"""


def campaign_file(tmp_path: Path, body: str, *, scenario: str = "") -> Path:
    path = tmp_path / "campaign.toml"
    path.write_text(
        f"""
[scenario]
{scenario or 'fleet = "examples/ramp-gain/fleet.toml"'}
stop_time = 2.0
out = "{tmp_path / "out"}"
timeout = 120
{body}
""",
        encoding="utf-8",
    )
    return path


def table(path: Path) -> list[dict[str, str]]:
    with path.open(encoding="utf-8", newline="") as file:
        return list(csv.DictReader(file))


def assert_ramp_gain_table(rows: list[dict[str, str]]) -> None:
    """y = gain * slope * t at the last point (t = 1.9 s, the Jacobi delay of one step of
    0.1 s), its maximum; x integrates y."""
    assert len(rows) == 9
    assert sorted((float(r["Gain.gain"]), float(r["Source.slope"])) for r in rows) == [
        (g, s) for g in (1.0, 2.0, 3.0) for s in (0.5, 1.0, 2.0)
    ]
    for row in rows:
        gain, slope = float(row["Gain.gain"]), float(row["Source.slope"])
        assert row["status"] == "completed", row
        assert float(row["y_max"]) == pytest.approx(1.9 * gain * slope)
        assert float(row["x_final"]) == pytest.approx(gain * slope * 1.71, rel=1e-6)
        assert int(row["y_changes"]) == 19
        assert row["y_bounded"] == "true"
        assert float(row["wall_time_s"]) > 0 and float(row["realtime_factor"]) > 0


@pytest.fixture
def ramp_gain(fmus: dict[str, Path], monkeypatch: pytest.MonkeyPatch) -> Path:
    """Relative paths of campaign files are taken from the repository (the working folder)."""
    monkeypatch.chdir(REPO)
    return EXAMPLE


@pytest.mark.slow
def test_a_3x3_campaign_runs_in_parallel_and_a_second_run_skips_it(
    ramp_gain: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = campaign_file(tmp_path, GRID)
    assert main(["campaign", str(path), "--jobs", "2"]) == 0
    out = tmp_path / "out"
    rows = table(out / "campaign.csv")
    assert_ramp_gain_table(rows)
    printed = capsys.readouterr()
    assert "table: " in printed.out and "y_max" in printed.out
    assert "9/9 done, 0 failed" in printed.err
    for row in rows:  # every run's own files
        run = out / row["directory"]
        assert json.loads((run / "variant.json").read_text()) == {
            "Gain.gain": float(row["Gain.gain"]),
            "Source.slope": float(row["Source.slope"]),
        }
        assert json.loads((run / "summary.json").read_text())["status"] == "completed"
        assert (run / "results.csv").read_text().startswith("time,")
        command = (run / "run.log").read_text().splitlines()[0]
        assert "--param Gain.gain=" in command
        assert " --address grpc://" in command and "=unix:///" in command  # as coupler fleet
    stamps = {p: p.stat().st_mtime_ns for p in out.glob("runs/*/results.csv")}

    assert main(["campaign", str(path)]) == 0  # again: nothing runs
    assert "9 of 9 runs completed earlier" in capsys.readouterr().err
    assert {p: p.stat().st_mtime_ns for p in out.glob("runs/*/results.csv")} == stamps
    assert table(out / "campaign.csv") == rows


@pytest.mark.slow
async def test_the_same_campaign_on_a_dask_local_cluster(ramp_gain: Path, tmp_path: Path) -> None:
    spec = CampaignSpec.load(campaign_file(tmp_path, GRID))
    result = await run_campaign(spec, jobs=2, scheduler="local")
    assert result.skipped == 0 and not result.failed
    rows = table(result.table_csv)
    assert_ramp_gain_table(rows)
    workers = {r.worker for r in result.reports}
    assert workers  # the runs ran in the cluster's worker processes
    assert result.table_parquet is not None and result.table_parquet.is_file()


@pytest.mark.slow
@pytest.mark.timeout(600)  # a Dask cluster and two fleets, from a process of its own
def test_a_campaign_on_dask_prints_only_its_own_lines_and_leaves_no_logs_behind(
    ramp_gain: Path, tmp_path: Path
) -> None:
    """``coupler campaign --scheduler local`` as a user runs it: the workers log as the command
    does (WARNING: no INFO line of theirs), and the runs' services leave no build/logs/fleet-*
    folder (a completed run's service logs go with its scratch folder)."""
    path = campaign_file(
        tmp_path, '[[variant]]\n"Gain.gain" = 2.0\n\n[[variant]]\n"Gain.gain" = 3.0\n'
    )
    logs = REPO / "build" / "logs"
    before = set(logs.iterdir()) if logs.is_dir() else set()
    done = subprocess.run(
        [Path(sys.executable).with_name("coupler"), "campaign", path, "--scheduler", "local",
         "--jobs", "2"],
        cwd=REPO, capture_output=True, text=True, timeout=600, stdin=subprocess.DEVNULL,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert [r["status"] for r in table(tmp_path / "out" / "campaign.csv")] == ["completed"] * 2
    assert all(line.startswith("campaign: ") for line in done.stderr.splitlines()), done.stderr
    after = set(logs.iterdir()) if logs.is_dir() else set()
    assert after == before


@pytest.mark.slow
def test_a_failing_run_is_a_row_and_the_others_complete(
    ramp_gain: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = campaign_file(
        tmp_path,
        """
[[variant]]
"Gain.gain" = 2.0

[[variant]]
"Gain.no_such_parameter" = 1.0

[[variant]]
"Gain.gain" = 3.0
stop_time = 1.0

[outputs]
y_final = "Gain.y"
""",
    )
    assert main(["campaign", str(path)]) == 1
    err = capsys.readouterr().err
    assert "1 of 3 runs did not complete" in err
    rows = table(tmp_path / "out" / "campaign.csv")
    assert [r["status"] for r in rows] == ["completed", "failed", "completed"]
    assert "no_such_parameter" in rows[1]["reason"]
    assert float(rows[0]["y_final"]) == pytest.approx(2 * 0.5 * 1.9)  # slope 0.5 (the SSD)
    assert float(rows[2]["y_final"]) == pytest.approx(3 * 0.5 * 0.9)  # its own stop time
    assert rows[1]["y_final"] == ""
    folders = [tmp_path / "out" / r["directory"] for r in rows]
    assert "participant_serving" in (folders[1] / "service-gain.log").read_text()  # its service
    assert not any((f / "service-gain.log").exists() for f in (folders[0], folders[2]))

    assert main(["campaign", str(path)]) == 1  # again: only the failed run runs again
    assert "2 of 3 runs completed earlier" in capsys.readouterr().err
    assert main(["campaign", str(path), "--force", "--jobs", "1"]) == 1
    assert "completed earlier" not in capsys.readouterr().err


def fleets_of(out: Path, rows: list[dict[str, str]]) -> list[str]:
    """The private socket folder each run reached its services in (``run.log``'s command)."""
    found = []
    for row in rows:
        command = (out / row["directory"] / "run.log").read_text().splitlines()[0]
        address = command.split("=unix://", 1)[1].split()[0]
        found.append(str(Path(address).parent))
    return found


KEPT = """
[[variant]]
"Gain.gain" = 1.0

[[variant]]
"Gain.gain" = 2.0

[[variant]]
"Gain.no_such_parameter" = 1.0

[[variant]]
"Gain.gain" = 3.0

[[variant]]
"Gain.gain" = 4.0

[outputs]
y_max = "max(Gain.y)"
x_final = "Integrator.x"
"""


@pytest.mark.slow
@pytest.mark.parametrize("scheduler", [[], ["--scheduler", "local"]], ids=["here", "dask"])
def test_kept_services_serve_run_after_run_with_the_same_results(
    ramp_gain: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], scheduler: list[str]
) -> None:
    """``keep_services = true``: one run at a time (--jobs 1) takes the fleet the run before
    left, so five runs start two fleets (the failed run's is not kept); every value is the one
    of the same campaign with services of their own, and the services end with the campaign
    (the hygiene check fails a test that leaves a process or a temporary folder)."""
    (tmp_path / "kept").mkdir(), (tmp_path / "own").mkdir()
    kept = campaign_file(tmp_path / "kept", KEPT, scenario=(
        'fleet = "examples/ramp-gain/fleet.toml"\nkeep_services = true'))  # fmt: skip
    own = campaign_file(tmp_path / "own", KEPT)
    assert main(["campaign", str(kept), "--jobs", "1", *scheduler]) == 1  # the failed run
    assert main(["campaign", str(own), "--jobs", "1"]) == 1
    capsys.readouterr()
    rows = table(tmp_path / "kept" / "out" / "campaign.csv")
    alone = table(tmp_path / "own" / "out" / "campaign.csv")
    values = ("Gain.gain", "status", "y_max", "x_final")
    assert [{k: r.get(k) for k in values} for r in rows] == [
        {k: r.get(k) for k in values} for r in alone
    ]
    assert [r["status"] for r in rows] == ["completed", "completed", "failed"] + ["completed"] * 2
    fleets = fleets_of(tmp_path / "kept" / "out", rows)
    assert fleets[0] == fleets[1] == fleets[2] != fleets[3] == fleets[4]
    assert len(set(fleets_of(tmp_path / "own" / "out", alone))) == 5
    failed = tmp_path / "kept" / "out" / rows[2]["directory"]
    assert "participant_serving" in (failed / "service-gain.log").read_text()  # its services'
    assert not any(Path(f).exists() for f in fleets)


@pytest.fixture
def gain_pool(fmus: dict[str, Path]) -> Iterator[list[int]]:
    """Two gain participants already running, each its own process."""
    ports = [free_port(), free_port()]
    with contextlib.ExitStack() as processes:
        for port in ports:
            command = [sys.executable, "-m", "coupler.examples", "gain", "--port", str(port)]
            quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
            processes.enter_context(process_group(command, **quiet))
        for port in ports:
            asyncio.run(wait_until_serving(f"grpc://127.0.0.1:{port}"))
        yield ports


@pytest.mark.slow
def test_a_pool_of_running_participants_serves_one_run_each(
    ramp_gain: Path, gain_pool: list[int], tmp_path: Path
) -> None:
    pool = ", ".join(f'{{ GAIN_PORT = "{port}" }}' for port in gain_pool)
    path = campaign_file(
        tmp_path,
        GRID + f"\n[pool]\nenv = [{pool}]\n",
        scenario='ssp = "examples/ramp-gain/SystemStructure.ssd"',
    )
    # 4 asked, 2 at once (the pool's size): a participant serves one run at a time and refuses
    # a second, which would fail that run
    assert main(["campaign", str(path), "--jobs", "4"]) == 0
    assert_ramp_gain_table(table(tmp_path / "out" / "campaign.csv"))


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ("[grids]\n", "[grids]: unknown section"),
        ("keep_service = true\n", "[scenario]: unknown key 'keep_service'; keys are args,"),
        ('keep_services = "yes"\n', "[scenario]: keep_services must be true or false"),
        ('[grid]\n"gain" = [1]\n', "'gain' is neither Component.parameter"),
        ('[grid]\n"Gain.gain" = 2\n', "'Gain.gain' is not a list of values"),
        ('[outputs]\ny = "median(Gain.y)"\n', "is not a channel or a reduction of one"),
        ('[outputs]\nr = "max(reports.perception.recall)"\n', "a report's value is one value"),
        ("[checks]\nok = \"__import__('os')\"\n", "Call is not allowed"),
        ('[sample]\nn = 3\n"Gain.gain" = { normal = [1, 2] }\n', "'Gain.gain' has no law"),
        ('[table]\nfile = "missing.csv"\n', "cannot read"),
        ('[[derive]]\nfunction = "nothing"\n', "'nothing' is not module:function"),
        (
            '[[derive]]\nfunction = "no_such_module:f"\n',
            "function = 'no_such_module:f' cannot be loaded (ModuleNotFoundError",
        ),
        ('[[derive]]\nfunction = "json:nothing"\n', "cannot be loaded (AttributeError"),
        (
            '[[variant]]\n"Gain.gain" = 1\n[[variant]]\n"Gain.gain" = 2\nstop_time = "abc"\n',
            "[variant]: variant 2 has stop_time = 'abc', which is not a number of seconds > 0",
        ),
        ("[grid]\nstep = [0.1, 0]\n", "variant 2 has step = 0, which is not a number"),
    ],
)
def test_campaign_files_that_cannot_run_are_refused(
    ramp_gain: Path, tmp_path: Path, body: str, message: str
) -> None:
    path = campaign_file(tmp_path, body)
    with pytest.raises(CampaignError) as caught:
        CampaignSpec.load(path)
    assert str(path) in str(caught.value) and message in str(caught.value)


def test_the_cli_says_what_is_wrong_with_a_campaign_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = campaign_file(tmp_path, "", scenario='ssp = "nowhere.ssd"')
    assert main(["campaign", str(path)]) == 1
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "nowhere.ssd does not exist" in err
    assert "Traceback" not in err


def test_variants_from_a_table_and_from_a_seeded_sample(ramp_gain: Path, tmp_path: Path) -> None:
    (tmp_path / "variants.csv").write_text("Gain.gain,stop_time\n1.5,1.0\n2.5,\n")
    sampled = '[sample]\nn = 4\nseed = 7\n"Gain.gain" = { uniform = [0.5, 2.0] }\n'
    spec = CampaignSpec.load(campaign_file(tmp_path, '[table]\nfile = "variants.csv"\n' + sampled))
    assert spec.variants[:2] == ({"Gain.gain": 1.5, "stop_time": 1}, {"Gain.gain": 2.5})
    drawn = [v["Gain.gain"] for v in spec.variants[2:]]
    assert len(drawn) == 4 and all(0.5 <= float(g) <= 2.0 for g in drawn)
    again = CampaignSpec.load(campaign_file(tmp_path, '[table]\nfile = "variants.csv"\n' + sampled))
    assert again.variants == spec.variants  # the seed makes the sample reproducible


@pytest.mark.parametrize(
    ("csv_bytes", "message"),
    [
        (b"Gain.gain\n1.5\n\xe9t\xe9\n", "variants.csv:3: not UTF-8 (byte 0xe9 at column 1)"),
        (
            b"Gain.gain,stop_time,Gain.gain\n1,2,3\n",
            "variants.csv:1: column 3: 'Gain.gain' is also column 1",
        ),
        (b"Gain.gain\n", "variants.csv has a header and no row"),
        (b"", "variants.csv is empty"),
        (b"Gain.gain,\n1,2\n", "variants.csv:1: column 2: '' is not a key"),
        (b"Gain.gain\n1\n2,3\n", "variants.csv:3: 2 cells, the header has 1"),
        (b'Gain.gain\n"1\n', "variants.csv:2: unexpected end of data"),
    ],
    ids=["latin-1", "duplicate-header", "header-only", "empty", "empty-key", "cells", "quote"],
)
def test_bad_variant_tables_are_refused_naming_line_and_column(
    ramp_gain: Path, tmp_path: Path, csv_bytes: bytes, message: str
) -> None:
    """Each used to be a traceback (UnicodeDecodeError) or accepted silently (the second
    column of a name replacing the first; a header alone: one run with no variant)."""
    (tmp_path / "variants.csv").write_bytes(csv_bytes)
    path = campaign_file(tmp_path, '[table]\nfile = "variants.csv"\n')
    with pytest.raises(CampaignError) as caught:
        CampaignSpec.load(path)
    assert str(path) in str(caught.value) and message in str(caught.value), caught.value


def test_a_table_with_a_byte_order_mark_reads_its_first_key(
    ramp_gain: Path, tmp_path: Path
) -> None:
    """A spreadsheet's "CSV UTF-8" starts with a byte order mark: it is not part of the first
    key (it used to be: a parameter named '\\ufeffGain.gain')."""
    (tmp_path / "variants.csv").write_bytes(b"\xef\xbb\xbfGain.gain,stop_time\n1.5,1\n")
    spec = CampaignSpec.load(campaign_file(tmp_path, '[table]\nfile = "variants.csv"\n'))
    assert list(spec.variants) == [{"Gain.gain": 1.5, "stop_time": 1}]


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ('n = 3\n"Gain.gain" = { uniform = ["a", 2] }', "uniform = ['a', 2] is not [low, high]"),
        ('n = 3\n"Gain.gain" = { uniform = [3, 2] }', "uniform = [3, 2] is not [low, high]"),
        ('n = 3\n"Gain.gain" = { uniform = [1] }', "uniform = [1] is not [low, high]"),
        ('n = 3\n"Gain.gain" = { uniform = 2 }', "uniform = 2 is not [low, high]"),
        ('n = 3\n"Gain.gain" = { uniform = [0, inf] }', "uniform = [0, inf] is not"),
        ('n = 3\n"Gain.gain" = { choice = [] }', "choice = []"),
        ('n = 3\n"Gain.gain" = { choice = [[1]] }', "'Gain.gain' = [1] is not a number"),
        ('n = 0\n"Gain.gain" = { choice = [1] }', "n = 0 is not between 1 and 100,000"),
        ('n = 2.5\n"Gain.gain" = { choice = [1] }', "both must be whole numbers"),
        ('n = "ten"\n"Gain.gain" = { choice = [1] }', "both must be whole numbers"),
    ],
)
def test_bad_samples_are_refused(ramp_gain: Path, tmp_path: Path, body: str, message: str) -> None:
    """Bounds that are not two ordered finite numbers used to be tracebacks (ValueError,
    TypeError) or a silent sample of another range; n = 0 a campaign of one unvaried run."""
    path = campaign_file(tmp_path, f"[sample]\n{body}\n")
    with pytest.raises(CampaignError) as caught:
        CampaignSpec.load(path)
    assert f"{path} [sample]" in str(caught.value) and message in str(caught.value), caught.value


@pytest.mark.parametrize(
    ("expression", "message"),
    [
        ("'x' * 100000000000 == 'x'", "a text cannot be computed with"),
        ("y_max * 'x' > 1", "a text cannot be computed with"),
        ("y_max > " + "9" * 5000, "characters, more than 1000"),
        ("(" * 300 + "1" + ")" * 300 + " > 0", "not an expression"),
        ("y_max == b'x'", "b'x' is not a number or a text"),
    ],
    ids=["text-times-huge", "output-times-text", "huge-number", "nested", "bytes"],
)
def test_checks_that_cannot_be_evaluated_are_refused(
    ramp_gain: Path, tmp_path: Path, expression: str, message: str
) -> None:
    """A text multiplied by 10^11 used to be evaluated after each run (MemoryError)."""
    body = f'[outputs]\ny_max = "max(Gain.y)"\n[checks]\nok = """{expression}"""\n'
    path = campaign_file(tmp_path, body)
    with pytest.raises(CampaignError) as caught:
        CampaignSpec.load(path)
    assert f"{path} [checks]" in str(caught.value) and message in str(caught.value), caught.value


def grid_of(axes: int, values: int) -> str:
    return "[grid]\n" + "".join(f'"Gain.p{i}" = {list(range(values))}\n' for i in range(axes))


@pytest.mark.parametrize(
    ("body", "message"),
    [
        (
            grid_of(6, 100),
            "[grid]: 1,000,000,000,000 variants (grid 1,000,000,000,000) are more than the "
            "100,000 a campaign may run",
        ),
        (
            '[sample]\nn = 1_000_000_000\n"Gain.gain" = { uniform = [1, 2] }\n',
            "[sample]: n = 1,000,000,000 is not between 1 and 100,000",
        ),
        (
            grid_of(5, 10) + '[sample]\nn = 1\n"Gain.gain" = { uniform = [1, 2] }\n',
            "100,001 variants (grid 100,000, sampled 1) are more than the 100,000",
        ),
    ],
    ids=["grid-1e12", "sample-1e9", "together"],
)
def test_campaigns_past_the_maximum_are_refused_at_once(
    ramp_gain: Path, tmp_path: Path, body: str, message: str
) -> None:
    """``coupler campaign`` as a user runs it, its address space held to 1.5 GB: refused in one
    sentence before any variant is made (it used to grow to 3.75 GB, then MemoryError)."""
    path = campaign_file(tmp_path, body)

    def limited() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (1536 << 20, 1536 << 20))

    done = subprocess.run(
        [str(Path(sys.executable).with_name("coupler")), "campaign", str(path)],
        capture_output=True,
        text=True,
        timeout=120,
        preexec_fn=limited,
    )
    assert done.returncode == 1, done.stderr
    assert done.stderr.startswith(f"error: {path} ") and message in done.stderr, done.stderr
    assert "Traceback" not in done.stderr and "MemoryError" not in done.stderr


def test_variants_are_made_as_they_are_asked_for(ramp_gain: Path, tmp_path: Path) -> None:
    """A grid of 10,000 and a sample of 90,000: counted without being made; any one of them,
    or a slice, is made on demand and equals what iterating gives."""
    body = (
        grid_of(4, 10) + '[sample]\nn = 90000\nseed = 3\n"Gain.gain" = { uniform = [0.5, 2.0] }\n'
    )
    spec = CampaignSpec.load(campaign_file(tmp_path, body))
    assert len(spec.variants) == 100_000
    assert spec.variants[0] == {"Gain.p0": 0, "Gain.p1": 0, "Gain.p2": 0, "Gain.p3": 0}
    assert spec.variants[1234] == {"Gain.p0": 1, "Gain.p1": 2, "Gain.p2": 3, "Gain.p3": 4}
    assert spec.variants[9999] == {"Gain.p0": 9, "Gain.p1": 9, "Gain.p2": 9, "Gain.p3": 9}
    assert spec.variants[9998:10003:2][1] == spec.variants[10000]
    assert spec.variants[-1] == list(spec.variants)[-1]
    assert 0.5 <= float(spec.variants[10000]["Gain.gain"]) <= 2.0


def test_reductions() -> None:
    cells = ["1.0", "3.5", "3.5", "-2.0", "0.5"]
    found = {
        name: reduce(Output(name=name, reduction=name, channel="A.b"), cells)
        for name in ("max", "min", "first", "last", "mean", "count_changes")
    }
    assert found == {
        "max": 3.5,
        "min": -2.0,
        "first": 1.0,
        "last": 0.5,
        "mean": pytest.approx(6.5 / 5),
        "count_changes": 3,
    }
    assert reduce(Output(name="x", reduction="last", channel="A.b"), []) is None
    # an Integer column's extremes are whole numbers as it has them (3, never 3.0)
    counts = ["1", "3", "", "2"]
    for name, expected in (("max", 3), ("min", 1)):
        found_int = reduce(Output(name=name, reduction=name, channel="A.n"), counts)
        assert (found_int, type(found_int)) == (expected, int)


def test_report_values_are_read_off_the_summary() -> None:
    bins = [{"recall": None}, {"recall": 1.0}]
    summary = {"reports": {"perception": {"recall": 0.5, "by_distance": bins}}}
    assert report_value(summary, "reports.perception.recall") == 0.5
    assert report_value(summary, "reports.perception.by_distance.1.recall") == 1.0
    assert report_value(summary, "reports.perception.by_distance.7.recall") is None
    assert report_value(summary, "reports.other.recall") is None
    assert report_value(summary, "reports.perception.by_distance.0") == '{"recall": null}'


def test_a_table_without_timings_is_the_same_for_the_same_runs(
    ramp_gain: Path, tmp_path: Path
) -> None:
    """``[scenario] timings = false``: no wall time in campaign.csv, so two campaigns whose runs
    gave the same values write the same bytes; a timings that is no boolean is refused."""
    path = campaign_file(tmp_path, GRID, scenario='fleet = "examples/ramp-gain/fleet.toml"\n'
                         "timings = false")  # fmt: skip
    spec = CampaignSpec.load(path)
    assert not spec.timings
    tables = []
    for wall_time in (1.5, 2.5):
        report = RunReport(index=1, key="k", variant={"Gain.gain": 1.0}, status="completed",
                           wall_time_s=wall_time, realtime_factor=1 / wall_time,
                           values={"y_max": 1.9})  # fmt: skip
        spec.out.mkdir(parents=True, exist_ok=True)
        write_table(spec, [report])
        tables.append((spec.out / "campaign.csv").read_bytes())
    assert tables[0] == tables[1]
    assert b"wall_time_s" not in tables[0] and b"y_max" in tables[0]
    timed = CampaignSpec.load(campaign_file(tmp_path, GRID))
    assert timed.timings
    bad = campaign_file(tmp_path, GRID, scenario='fleet = "examples/ramp-gain/fleet.toml"\n'
                        'timings = "no"')  # fmt: skip
    with pytest.raises(CampaignError, match=r"\[scenario\]: timings = 'no' is not true or false"):
        CampaignSpec.load(bad)
