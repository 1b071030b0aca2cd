"""What the orchestrator's tests share besides fixtures (those are in conftest.py files, found
by pytest): the ``coupler`` CLI run in-process or as a process, real gRPC participants served
in a thread, the project's FMUs in an SSD, and the repository's and the test data's folders.
Tests import it: ``from ..support import Coupler, serving`` (``from .support`` at the top).
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import os
import subprocess
import sys
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from coupler.channels import Causality, Channel, Description, RunSetup, Value, ValueType
from coupler.examples.gain import GainParticipant
from coupler.participant import Participant, Values
from coupler.security import ServerSecurity
from coupler.server import ParticipantServer
from coupler.testing import Component, Connector, fmu, served_in_thread
from coupler_orchestrator import native
from coupler_orchestrator.cli.main import main

REPO = Path(__file__).resolve().parents[4]
DATA = Path(__file__).resolve().parents[1] / "data"


def project_fmu(name: str, model: str, *connectors: Connector, **options: Any) -> Component:
    """Component ``name`` of an SSD: the project's FMU ``model`` ("Source2") in the folder
    ``${COUPLER_FMU_DIR}`` names (the ``fmus`` fixture sets it); ``options``: ``fmu``'s."""
    return fmu(name, f"${{COUPLER_FMU_DIR}}/{model}.fmu", *connectors, **options)


@dataclass(frozen=True)
class Outcome:
    """What one ``coupler`` command did."""

    code: int
    out: str
    err: str


class Coupler:
    """Runs the ``coupler`` CLI in-process (or, ``process``, as the user does: a command of its
    own) and reads what a run recorded."""

    def __init__(self, capsys: pytest.CaptureFixture[str]) -> None:
        self.capsys = capsys

    def __call__(self, *argv: str | Path) -> Outcome:
        self.capsys.readouterr()
        stdout = io.StringIO()
        code = main([str(a) for a in argv], stdout=stdout)
        return Outcome(code, stdout.getvalue(), self.capsys.readouterr().err)

    @staticmethod
    def process(
        *argv: str | Path,
        timeout: float = 120,
        env: Mapping[str, str] | None = None,
        cwd: Path | None = None,
    ) -> Outcome:
        """``coupler ARGV...`` as a process of its own (the installed console script), stdin
        and stderr not a terminal: only what the command itself imports is imported."""
        script = Path(sys.executable).with_name("coupler")
        command = (
            [str(script)] if script.exists() else [sys.executable, "-m", "coupler_orchestrator"]
        )
        done = subprocess.run(
            [*command, *(str(a) for a in argv)],
            capture_output=True,
            text=True,
            timeout=timeout,
            stdin=subprocess.DEVNULL,
            env=None if env is None else {**os.environ, **env},
            cwd=cwd,
        )
        return Outcome(done.returncode, done.stdout, done.stderr)

    @staticmethod
    def results(out_dir: Path) -> list[dict[str, str]]:
        """results.csv as one dict per row (header -> cell text)."""
        with (out_dir / "results.csv").open(newline="") as file:
            return list(csv.DictReader(file))

    @staticmethod
    def column(out_dir: Path, name: str) -> list[float]:
        """One column of results.csv as floats."""
        return [float(row[name]) for row in Coupler.results(out_dir)]

    @staticmethod
    def summary(out_dir: Path) -> dict[str, Any]:
        return json.loads((out_dir / "summary.json").read_text())  # type: ignore[no-any-return]


def require_native(module: native.NativeModule) -> None:
    """A module of coupler-native, loaded from the installed package (one that does not load
    fails the test; only coupler-native not installed at all skips it, saying so)."""
    if module() is None:
        if module.problem == native.MISSING:
            pytest.skip(module.problem)
        pytest.fail(f"{module.what}: {module.problem}")


def serving(
    participant: Participant, security: ServerSecurity | None = None, **options: Any
) -> contextlib.AbstractContextManager[ParticipantServer]:
    """``participant`` served on 127.0.0.1, port 0 (or as ``options`` say, e.g. on a
    ``unix_socket``), by a loop in a background thread, so that a test can call the ``coupler``
    CLI (which runs its own loop) in-process."""
    return served_in_thread(participant, security=security, **options)


class FailingGain(GainParticipant):
    """The example gain participant, failing every DoStep that starts at t >= ``fail_at``."""

    def __init__(self, name: str = "Gain", *, fail_at: float = 1.0) -> None:
        super().__init__(name)
        self.fail_at = fail_at

    async def do_step(self, time: float, step: float, inputs: Mapping[str, object]) -> Values:
        if time >= self.fail_at:
            raise RuntimeError(f"gain overheated at t={time:g}")
        return await super().do_step(time, step, inputs)  # type: ignore[arg-type]


class Stepper(Participant):
    """Enumerations over gRPC: ``phase`` = steps done mod 2; ``shown`` = ``aspect`` as received.

    ``aspect`` has no start value: it must be connected or bound in the SSD.
    """

    CHANNELS = (
        Channel(name="aspect", causality=Causality.INPUT, type=ValueType.ENUMERATION),
        Channel(name="phase", causality=Causality.OUTPUT, type=ValueType.ENUMERATION),
        Channel(name="shown", causality=Causality.OUTPUT, type=ValueType.ENUMERATION),
    )

    def __init__(self) -> None:
        self._steps = 0
        self._aspect: Value = 0

    async def describe(self) -> Description:
        return Description(name="Stepper", channels=self.CHANNELS, implementation="tests.Stepper")

    async def initialize(self, setup: RunSetup) -> Values:
        self._steps, self._aspect = 0, setup.inputs.get("aspect", 0)
        return self._outputs()

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        self._steps += 1
        self._aspect = inputs.get("aspect", self._aspect)
        return self._outputs()

    async def terminate(self, reason: str = "") -> None:
        self._steps = 0

    def _outputs(self) -> Values:
        return {"phase": self._steps % 2, "shown": self._aspect}
