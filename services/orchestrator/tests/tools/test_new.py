"""``coupler new participant NAME`` writes a participant that runs as it is::

coupler new participant Heater  -->  Heater/participant.py  (served as a process)
                                     Heater/Heater.ssd      (coupler run, a process)
                                     Heater/fleet.toml      (coupler fleet, a process)
                                     Heater/README.md

Heater (gRPC, gain 2, u bound to 0.5):  y = gain * u = 1,  x += y * h  (h = 0.1, to 1 s)
Mini (--template minimal, k 2, u bound to 0.5):  y = k * u = 1
"""

from __future__ import annotations

import asyncio
import csv
import importlib.util
import json
import os
import re
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from coupler.testing import free_port, process_group, wait_until_serving

COUPLER = str(Path(sys.executable).with_name("coupler"))
RUFF = Path(sys.executable).with_name("ruff")


def coupler(*args: str | Path, cwd: Path, **env: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [COUPLER, *map(str, args)],
        cwd=cwd,
        env={**os.environ, **env},
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_the_written_participant_runs_as_it_is(tmp_path: Path) -> None:
    made = coupler("new", "participant", "Heater", cwd=tmp_path)
    assert made.returncode == 0, made.stderr
    folder = tmp_path / "Heater"
    assert sorted(p.name for p in folder.iterdir()) == [
        "Heater.ssd",
        "README.md",
        "fleet.toml",
        "participant.py",
    ]
    assert "coupler run Heater.ssd" in (folder / "README.md").read_text()

    port = free_port()
    serving = [sys.executable, "participant.py", "--port", str(port)]
    with process_group(serving, cwd=folder, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE):
        asyncio.run(wait_until_serving(f"grpc://127.0.0.1:{port}"))
        ran = coupler("run", "Heater.ssd", "--out", "results", cwd=folder, HEATER_PORT=str(port))
    assert ran.returncode == 0, ran.stderr

    with (folder / "results" / "results.csv").open() as results:
        rows = list(csv.DictReader(results))
    assert [float(r["time"]) for r in rows] == pytest.approx([k / 10 for k in range(11)])
    x = 0.0  # what participant.py computes: gain 2 * u 0.5 per step of 0.1 s
    for row in rows:
        assert float(row["Heater.y"]) == 1.0
        assert float(row["Heater.x"]) == x
        x += 1.0 * 0.1


@pytest.mark.slow
@pytest.mark.parametrize("template", ["integrator", "minimal"])
def test_the_written_participant_drops_into_a_fleet(tmp_path: Path, template: str) -> None:
    """A fleet file with the participant as a ``[[service]]`` and nothing but the defaults:
    ``coupler fleet`` serves it on a unix socket (it adds ``--socket PATH``, which the program
    takes) and steps it over the step socket beside it. The fleet file is the one written with
    it, as a user copies the service into theirs."""
    made = coupler("new", "participant", "Mini", "--template", template, cwd=tmp_path)
    assert made.returncode == 0, made.stderr
    folder = tmp_path / "Mini"
    fleet = (folder / "fleet.toml").read_text()
    assert "socket" not in fleet.split("[[service]]")[1]  # the defaults: unix sockets on
    ran = coupler("fleet", "fleet.toml", "--exit", cwd=folder, MINI_PORT=str(free_port()))
    assert ran.returncode == 0, ran.stdout + ran.stderr
    assert "participants on unix sockets in" in ran.stdout
    assert re.search(r"^completed: 10 steps to t=1 s", ran.stdout, re.MULTILINE), ran.stdout
    run = folder / "results" / "latest"
    summary = json.loads((run / "summary.json").read_text())
    assert summary["status"] == "completed"
    if importlib.util.find_spec("coupler_native._step_streams") is not None:
        stepped = summary["participants"]["Mini"]["step_path"]
        assert stepped["path"] == "native step socket"
        assert stepped["reason"].endswith("/Mini.sock.steps, without gRPC")
    with (run / "results.csv").open() as results:
        rows = list(csv.DictReader(results))
    assert len(rows) == 11 and {r["Mini.y"] for r in rows} == {"1.0"}


def test_the_written_participant_says_in_one_line_that_its_port_is_taken(
    tmp_path: Path,
) -> None:
    assert coupler("new", "participant", "Heater", cwd=tmp_path).returncode == 0
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        served = subprocess.run(
            [sys.executable, "participant.py", "--port", str(port)],
            cwd=tmp_path / "Heater",
            capture_output=True,
            text=True,
            timeout=60,
        )
    assert served.returncode == 1
    assert "Traceback" not in served.stderr
    [line] = served.stderr.splitlines()
    assert line.startswith(f"participant.py: cannot serve the participant on 127.0.0.1:{port}: ")
    assert f"the port is in use by pid {os.getpid()} (" in line


@pytest.mark.parametrize("template", ["integrator", "minimal"])
def test_the_written_program_is_clean(tmp_path: Path, template: str) -> None:
    """What the command writes passes the project's own lint and format rules."""
    written = coupler("new", "participant", "cooler_2", "--dir", "c", "--template", template,
                      cwd=tmp_path)  # fmt: skip
    assert written.returncode == 0, written.stderr
    program = tmp_path / "c" / "participant.py"
    assert "class Cooler_2Participant(Participant):" in program.read_text()
    for check in (["check"], ["format", "--check"]):
        linted = subprocess.run(
            [RUFF, *check, program], cwd=Path(__file__).parent, capture_output=True, text=True
        )
        assert linted.returncode == 0, linted.stdout + linted.stderr


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["2Heater"], "'2Heater' cannot name a participant: use a letter, then letters"),
        (["Heat er"], "'Heat er' cannot name a participant"),
        (["Heater", "--dir", "taken"], "taken exists; coupler new writes a new folder"),
    ],
)
def test_a_wrong_name_or_an_existing_folder_is_refused(
    tmp_path: Path, args: list[str], expected: str
) -> None:
    (tmp_path / "taken").mkdir()
    (tmp_path / "taken" / "mine.txt").write_text("kept")
    refused = coupler("new", "participant", *args, cwd=tmp_path)
    assert refused.returncode == 2
    assert expected in refused.stderr
    assert "Traceback" not in refused.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["taken"]
    assert (tmp_path / "taken" / "mine.txt").read_text() == "kept"
