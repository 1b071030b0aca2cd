"""``coupler new participant NAME`` writes a participant that runs as it is::

coupler new participant Heater  -->  Heater/participant.py  (served as a process)
                                     Heater/Heater.ssd      (coupler run, a process)
                                     Heater/README.md

Heater (gRPC, gain 2, u bound to 0.5):  y = gain * u = 1,  x += y * h  (h = 0.1, to 1 s)
"""

from __future__ import annotations

import asyncio
import csv
import json
import os
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
    assert sorted(p.name for p in folder.iterdir()) == ["Heater.ssd", "README.md", "participant.py"]
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


FLEET = """
[scenario]
ssp = "Heater/Heater.ssd"
out = "results"

[[service]]
name = "heater"
command = ["python", "Heater/participant.py", "--port", "${HEATER_PORT:-50080}"]
health = "grpc://127.0.0.1:${HEATER_PORT:-50080}"
"""


def test_the_written_participant_drops_into_a_fleet(tmp_path: Path) -> None:
    """``coupler fleet`` serves it on a unix socket (``--socket``) and steps it over its step
    socket, as every service of a fleet: the template takes every option a fleet passes
    (``coupler.main``; it used to take only ``--port``: "unrecognized arguments: --socket")."""
    assert coupler("new", "participant", "Heater", cwd=tmp_path).returncode == 0
    (tmp_path / "fleet.toml").write_text(FLEET, encoding="utf-8")
    ran = coupler("fleet", "fleet.toml", "--exit", cwd=tmp_path, HEATER_PORT=str(free_port()))
    assert ran.returncode == 0, ran.stderr
    assert "completed: 10 steps to t=1 s" in ran.stdout
    summary = json.loads((tmp_path / "results" / "latest" / "summary.json").read_text())
    assert summary["participants"]["Heater"]["step_path"]["path"] == "native step socket"


def test_a_busy_port_is_one_line(tmp_path: Path) -> None:
    """The written participant on a port another process holds: exit 1 and one sentence naming
    the port and its holder (it printed a traceback)."""
    assert coupler("new", "participant", "Heater", cwd=tmp_path).returncode == 0
    with socket.socket() as holder:
        holder.bind(("127.0.0.1", 0))
        holder.listen()
        port = holder.getsockname()[1]
        served = subprocess.run(
            [sys.executable, "participant.py", "--port", str(port)],
            cwd=tmp_path / "Heater",
            capture_output=True,
            text=True,
            timeout=60,
        )
    assert served.returncode == 1, served.stderr
    assert "Traceback" not in served.stderr
    assert served.stderr.splitlines()[-1].startswith(
        f"Heater: cannot serve the participant on 127.0.0.1:{port}: the port is in use by pid "
    )


def test_the_written_program_is_clean(tmp_path: Path) -> None:
    """What the command writes passes the project's own lint and format rules."""
    assert coupler("new", "participant", "cooler_2", "--dir", "c", cwd=tmp_path).returncode == 0
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
