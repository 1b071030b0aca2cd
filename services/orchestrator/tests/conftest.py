"""Fixtures of the orchestrator's run-time tests: real FMUs and real gRPC participants.

FMUs are built once per session from the project's C sources (fmus/) with gcc and FMPy's FMI
headers. gRPC participants are real ParticipantServers on port 0, each on an event loop of its
own thread, so that tests can call the ``coupler`` CLI (which runs its own loop) in-process.
"""

from __future__ import annotations

import importlib.abc
import sys
from collections.abc import Iterator
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import pytest

from coupler.examples.gain import GainParticipant
from coupler.logs import configure_logging
from coupler.server import ParticipantServer
from coupler_orchestrator import native
from coupler_orchestrator.master import native_fmu_step as kernel
from coupler_orchestrator.master import native_step_channel as steps
from coupler_orchestrator.options import NATIVE_STEPS_VARIABLE
from coupler_orchestrator.outputs import csv as csv_output
from coupler_tools.fmubuild import build_all

from .support import REPO, Coupler, FailingGain, require_native, serving
from .support.frames import Fleet


@pytest.fixture(scope="session")
def built_fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """``{"Source2": path, "Feedthrough3": path, ...}`` built from fmus/ for this session.

    Into a private folder: other sessions may be building the same FMUs at the same time.
    """
    out = tmp_path_factory.mktemp("fmus")
    return {path.stem: path for path in build_all(REPO / "fmus", out)}


@pytest.fixture(scope="session")
def faulty_fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """``{"Faulty2": path, "Clocks3": path, ...}``: the FMUs of fmus/faulty (crash, hang, or
    must be refused; fmus/faulty/README.md), built for this session."""
    out = tmp_path_factory.mktemp("faulty-fmus")
    return {path.stem: path for path in build_all(REPO / "fmus" / "faulty", out)}


@pytest.fixture
def fmus(built_fmus: dict[str, Path], monkeypatch: pytest.MonkeyPatch) -> dict[str, Path]:
    """The built FMUs; ``${COUPLER_FMU_DIR}`` in the SSDs of data/ names their folder."""
    monkeypatch.setenv("COUPLER_FMU_DIR", str(next(iter(built_fmus.values())).parent))
    return built_fmus


class _Uninstalled(importlib.abc.MetaPathFinder):
    """Finds no coupler_native, as where the package is not installed."""

    def find_spec(self, name: str, path: Any, target: Any = None) -> None:
        if name == "coupler_native":
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)


@pytest.fixture
def without_coupler_native(monkeypatch: pytest.MonkeyPatch) -> None:
    """coupler-native as if it were not installed (a platform it has no wheel for)."""
    for name in [m for m in sys.modules if m.split(".")[0] == "coupler_native"]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setattr(sys, "meta_path", [_Uninstalled(), *sys.meta_path])
    monkeypatch.setattr(kernel, "library", native.NativeModule("_fmu_steps", "the FMU step"))
    monkeypatch.setattr(steps, "library", native.NativeModule("_step_streams", "the channel"))
    monkeypatch.setattr(csv_output, "native_rows", native.NativeModule("_rows", "the CSV row"))


@pytest.fixture(params=["native", "grpc.aio"])
def step_path(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    """Remote steps over the native step channel and over Python's grpc.aio."""
    if request.param == "native":
        require_native(steps.library)
    else:
        monkeypatch.setenv(NATIVE_STEPS_VARIABLE, "0")
    return str(request.param)


@pytest.fixture(params=["C", "Python"])
def fmu_path(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    """In-process FMUs stepped by the native FMU step (C; coupler-native's) and through Python
    (``COUPLER_NATIVE_STEPS=0``)."""
    if request.param == "C":
        require_native(kernel.library)
    else:
        monkeypatch.setenv(NATIVE_STEPS_VARIABLE, "0")
    return str(request.param)


@pytest.fixture
def coupler(capsys: pytest.CaptureFixture[str]) -> Coupler:
    """``coupler(*argv) -> Outcome`` plus readers of results.csv and summary.json."""
    return Coupler(capsys)


@pytest.fixture
def gain_server(monkeypatch: pytest.MonkeyPatch) -> Iterator[ParticipantServer]:
    """The example gain participant; its port is in ``$GAIN_PORT``."""
    with serving(GainParticipant()) as server:
        monkeypatch.setenv("GAIN_PORT", str(server.port))
        yield server


@pytest.fixture
def failing_gain_server(monkeypatch: pytest.MonkeyPatch) -> Iterator[ParticipantServer]:
    """A gain participant that fails at t >= 1.0; its port is in ``$GAIN_PORT``.

    Its own log of the failure is silenced: structlog would write it to a stream captured by
    an earlier test.
    """
    configure_logging("CRITICAL")
    with serving(FailingGain()) as server:
        monkeypatch.setenv("GAIN_PORT", str(server.port))
        yield server


@pytest.fixture
def fleet(monkeypatch: pytest.MonkeyPatch) -> Iterator[Fleet]:
    """Camera and Gain served in this process, once the test calls ``fleet.serve``."""
    with ExitStack() as stack:
        yield Fleet(stack, monkeypatch)
