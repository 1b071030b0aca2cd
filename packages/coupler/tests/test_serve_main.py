"""What a participant program gets from the SDK: ``serve_main`` (every option ``coupler fleet``
passes, one line on a problem) and ``step_end`` (a step's end on the run's decimal grid).

    python program.py --socket DIR/gain.sock   (a subprocess: serve_main(GainParticipant()))
        -> "serving Gain at unix://DIR/gain.sock", the step socket DIR/gain.sock.steps beside it,
           Describe over the socket; SIGTERM ends it with code 0
    python program.py --port TAKEN             -> one line naming the port and its holder, code 1
"""

from __future__ import annotations

import asyncio
import signal
import socket
import subprocess
import sys
from fractions import Fraction
from pathlib import Path

import pytest

from coupler import RemoteParticipant, step_end
from coupler.testing import process_group, wait_until_serving

PROGRAM = """\
from coupler import serve_main
from coupler.examples.gain import GainParticipant

serve_main(GainParticipant(), port=0, description="the gain example")
"""


@pytest.fixture
def program(tmp_path: Path) -> Path:
    path = tmp_path / "program.py"
    path.write_text(PROGRAM)
    return path


def test_serve_main_serves_on_the_socket_a_fleet_gives_and_the_step_socket_beside_it(
    program: Path, tmp_path: Path
) -> None:
    path = tmp_path / "gain.sock"
    command = [sys.executable, str(program), "--socket", str(path), "--log-level", "WARNING"]
    with process_group(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as p:
        assert p.stdout is not None
        assert p.stdout.readline() == f"serving Gain at unix://{path}\n"
        assert (tmp_path / "gain.sock.steps").is_socket()

        async def described() -> str:
            await wait_until_serving(f"unix://{path}")
            async with RemoteParticipant(f"unix://{path}") as remote:
                return (await remote.describe()).capabilities.step_socket

        assert asyncio.run(described()) == f"{path}.steps"
        p.send_signal(signal.SIGTERM)
        assert p.wait(30) == 0
        assert p.stderr is not None and p.stderr.read() == ""
    assert not path.exists()


def test_serve_main_lists_every_option_and_says_a_taken_port_in_one_line(program: Path) -> None:
    helped = subprocess.run(
        [sys.executable, str(program), "--help"], capture_output=True, text=True, timeout=60
    )
    assert helped.returncode == 0 and "the gain example" in helped.stdout
    for option in ("--host", "--port", "--socket", "--log-level", "--tls-cert", "--token-file"):
        assert option in helped.stdout, option
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        refused = subprocess.run(
            [sys.executable, str(program), "--port", str(port)],
            capture_output=True,
            text=True,
            timeout=60,
        )
    assert refused.returncode == 1
    [line] = refused.stderr.splitlines()  # the refusal, and nothing else
    assert line.startswith(
        f"program.py: cannot serve the participant on 127.0.0.1:{port}: the port is in use by "
    )


def test_step_end_is_the_next_point_of_the_decimal_grid() -> None:
    """Over 10,000 steps of 0.1 s and of 0.4 s (the railway's) from 0 and from 2.5: every step
    end is the double nearest to the exact decimal, where ``time + step`` misses often."""
    for start, step in ((0.0, 0.1), (0.0, 0.4), (2.5, 0.1), (2.5, 0.4)):
        exact = [Fraction(repr(start)) + k * Fraction(repr(step)) for k in range(10_001)]
        grid = [float(t) for t in exact]
        ends = [step_end(t, step) for t in grid[:-1]]
        assert ends == grid[1:], (start, step)
        missed = sum(t + step != end for t, end in zip(grid, ends, strict=False))
        assert missed > 1000, (start, step)  # what binary addition gives instead
        assert all(repr(t) == _decimal(x) for t, x in zip(ends, exact[1:], strict=True))


def _decimal(value: Fraction) -> str:
    """``value`` (a decimal of few digits) as Python prints a float: ``0.3``, ``12.0``."""
    text = f"{float(value):.6f}".rstrip("0")
    return text + "0" if text.endswith(".") else text
