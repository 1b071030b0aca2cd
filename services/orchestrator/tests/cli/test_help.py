"""What ``coupler --version`` and the commands' ``--help`` say, as a user reads them (the CLI
as a process): each says what the command does and takes."""

from __future__ import annotations

from importlib.metadata import version
from pathlib import Path

from coupler.examples.gain import GainParticipant
from coupler_orchestrator.outputs.files import RUN_FILES

from ..support import Coupler, serving


def test_version_names_the_orchestrator_and_the_sdk() -> None:
    outcome = Coupler.process("--version")
    assert outcome.code == 0, outcome.err
    assert outcome.out == (
        f"coupler {version('coupler-orchestrator')} (participant SDK: coupler "
        f"{version('coupler')}; protocol coupler.v1)\n"
    )


def test_new_help_names_its_one_kind_once_among_the_arguments() -> None:
    """It listed ``participant`` twice (a subcommand named by its own metavar)."""
    outcome = Coupler.process("new", "--help")
    assert outcome.code == 0, outcome.err
    usage, _, rest = outcome.out.partition("\n\n")
    assert usage.split()[-2:] == ["participant", "NAME"]
    listed = rest.split("positional arguments:\n", 1)[1].split("\n\n", 1)[0]
    assert [line.split()[0] for line in listed.splitlines()] == ["participant", "NAME"]


def test_describe_help_offers_unix_socket_targets_and_they_work(
    coupler: Coupler, tmp_path: Path
) -> None:
    outcome = Coupler.process("describe", "--help")
    assert outcome.code == 0, outcome.err
    assert "unix:///PATH" in " ".join(outcome.out.split())
    with serving(GainParticipant(), unix_socket=tmp_path / "gain.sock"):
        described = coupler("describe", f"unix://{tmp_path / 'gain.sock'}")
    assert described.code == 0, described.err
    assert described.out.startswith("Gain  (coupler.examples.gain)")


def test_run_help_names_every_file_and_folder_force_removes() -> None:
    """``--force`` removes RUN_FILES; the help named neither frames/ nor kept-frames/."""
    outcome = Coupler.process("run", "--help")
    assert outcome.code == 0, outcome.err
    force = " ".join(outcome.out.split("--force", 2)[2].split("--record", 1)[0].split())
    for name in RUN_FILES:
        assert (name if "." in name else f"{name}/") in force, (name, force)
