"""The declared public API of the two packages a user installs: ``coupler`` (the participant
SDK) and ``coupler_orchestrator`` (the orchestrator), as httpx's tests/test_exported_members.py
keeps its own. A name added to or taken from ``__all__`` is a decision, so it changes here too.
"""

from __future__ import annotations

import importlib
import subprocess
import sys
from types import ModuleType

import pytest

import coupler
import coupler_orchestrator

DECLARED = {
    "coupler": [
        "Adapter",
        "AdapterConfig",
        "AdapterParticipant",
        "Capabilities",
        "Causality",
        "Channel",
        "ChannelMap",
        "ChannelValueError",
        "ClientSecurity",
        "configure_logging",
        "CouplerError",
        "Description",
        "EndRun",
        "FmuParticipant",
        "HealthReport",
        "Participant",
        "ParticipantError",
        "ParticipantServer",
        "ParticipantSettings",
        "ParticipantTimeout",
        "ParticipantUnavailable",
        "register",
        "RemoteParticipant",
        "run",
        "RunSetup",
        "ScenarioError",
        "SecuritySettings",
        "serve",
        "ServerSecurity",
        "StepTransport",
        "ValidationError",
        "Value",
        "Values",
        "ValueType",
    ],
    "coupler_orchestrator": [
        "Algorithm",
        "Column",
        "Observer",
        "RunEnd",
        "RunInfo",
        "RunOptions",
        "RunOutcome",
        "run_scenario",
        "Validation",
        "validate_scenario",
    ],
}
PACKAGES = [coupler, coupler_orchestrator]


@pytest.mark.parametrize("package", PACKAGES, ids=lambda p: p.__name__)
def test_the_declared_names_are_the_public_api(package: ModuleType) -> None:
    assert sorted(package.__all__) == sorted(DECLARED[package.__name__])
    assert len(set(package.__all__)) == len(package.__all__)


@pytest.mark.parametrize("package", PACKAGES, ids=lambda p: p.__name__)
def test_every_public_name_is_the_object_its_module_defines(package: ModuleType) -> None:
    for name in package.__all__:
        value = getattr(package, name)
        home = importlib.import_module(f"{package.__name__}.{package._HOMES[name]}")
        assert value is getattr(home, name), name
        assert name in dir(package)
    with pytest.raises(AttributeError):
        package.NoSuchName  # noqa: B018


@pytest.mark.parametrize(
    ("package", "heavy"),
    [("coupler", ["grpc", "pydantic", "fmpy"]), ("coupler_orchestrator", ["grpc", "lxml"])],
)
def test_importing_a_package_imports_nothing_heavy(package: str, heavy: list[str]) -> None:
    """The names are imported when first used: ``import coupler`` in a participant's process or
    ``coupler --help`` pay for nothing they do not use."""
    code = f"import sys, {package}; print(sorted(m for m in {heavy!r} if m in sys.modules))"
    found = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    assert found.strip() == "[]"
