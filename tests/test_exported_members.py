"""The declared public API of the packages a user installs: ``coupler`` (the participant SDK),
``coupler_orchestrator`` (the orchestrator) and ``coupler_tools`` (the build helpers the services
use), as httpx's tests/test_exported_members.py keeps its own. A name added to or taken from
``__all__`` is a decision, so it changes here too.
"""

from __future__ import annotations

import importlib
import subprocess
import sys
from types import ModuleType

import pytest

import coupler
import coupler.fmu
import coupler_orchestrator
import coupler_tools
import coupler_tools.fmubuild
import coupler_tools.vendor

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
        "serve_main",
        "ServerSecurity",
        "step_end",
        "StepTransport",
        "ValidationError",
        "Value",
        "Values",
        "ValueType",
        "waiting",
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
    # the build helpers' API is their two modules, each declaring its own names
    "coupler.fmu": ["FmuParticipant"],
    "coupler_tools": ["fmubuild", "vendor"],
    "coupler_tools.fmubuild": [
        "FmuBuildError",
        "build_all",
        "build_fmu",
        "find_model_folders",
        "main",
        "write_archive",
    ],
    "coupler_tools.vendor": ["command", "copy", "missing"],
}
PACKAGES = [coupler, coupler_orchestrator]
"""Packages whose names are imported from their modules when first used (``_HOMES``)."""
MODULES = [coupler_tools.fmubuild, coupler_tools.vendor]
"""Modules that define every name they declare."""


@pytest.mark.parametrize(
    "package", [*PACKAGES, coupler.fmu, coupler_tools, *MODULES], ids=lambda p: p.__name__
)
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


def test_the_build_helpers_are_their_modules() -> None:
    for name in coupler_tools.__all__:
        assert importlib.import_module(f"coupler_tools.{name}") in MODULES


@pytest.mark.parametrize("module", MODULES, ids=lambda m: m.__name__)
def test_every_declared_name_is_defined_by_its_module(module: ModuleType) -> None:
    for name in module.__all__:
        assert getattr(module, name).__module__ == module.__name__, name


@pytest.mark.parametrize(
    ("package", "heavy"),
    [
        ("coupler", ["grpc", "pydantic", "fmpy"]),
        ("coupler_orchestrator", ["grpc", "lxml"]),
        # `coupler export-fmu` writes its archive and a map page checks its files without FMPy
        ("coupler_tools.fmubuild", ["grpc", "pydantic", "fmpy"]),
        ("coupler_tools.vendor", ["grpc", "pydantic", "fmpy"]),
    ],
)
def test_importing_a_package_imports_nothing_heavy(package: str, heavy: list[str]) -> None:
    """The names are imported when first used: ``import coupler`` in a participant's process or
    ``coupler --help`` pay for nothing they do not use."""
    code = f"import sys, {package}; print(sorted(m for m in {heavy!r} if m in sys.modules))"
    found = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    assert found.strip() == "[]"
