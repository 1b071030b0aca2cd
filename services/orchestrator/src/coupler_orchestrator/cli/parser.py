"""The ``coupler`` command line: the top-level parser, one subcommand per module of this package
(``COMMANDS``), and the options several commands share.

Nothing here imports what a command needs to run: a command module imports its dependencies
inside ``execute`` (as FMPy's ``cli.py`` does), so ``coupler --help`` answers at once.
"""

from __future__ import annotations

import argparse
import importlib
import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from coupler import durations
from coupler.errors import CouplerError
from coupler.values import MAX_MESSAGE_BYTES
from coupler_orchestrator.model import Algorithm

if TYPE_CHECKING:
    from coupler.security import ClientSecurity
    from coupler_orchestrator.options import RunOptions

MIN_REALTIME_FACTOR = 1e-3
"""The slowest pacing: one simulated second per 1000 s of wall time (slower would wait for
days between steps; 1e-300 never ended)."""

MAX_MESSAGE_MIB = 1024
"""The largest --max-message-size: gRPC and protobuf stop short of 2 GiB per message."""


def _message_size(text: str) -> float:
    """``--max-message-size``: MiB, above 0 and at most ``MAX_MESSAGE_MIB``."""
    try:
        size = float(text)
    except ValueError:
        size = math.nan
    if not 0 < size <= MAX_MESSAGE_MIB:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a size in MiB above 0 and at most {MAX_MESSAGE_MIB}"
        )
    return size


COMMANDS = {
    "run": "run",
    "validate": "validate",
    "fleet": "fleet",
    "campaign": "campaign",
    "plot": "plot",
    "replay": "replay",
    "export-fmu": "export_fmu",
    "describe": "describe",
    "new": "new",
}
"""Each command and its module in ``coupler_orchestrator.cli``, in the order ``--help`` lists
them. A module has ``HELP`` (and may have ``DESCRIPTION``), ``arguments(parser)`` and
``async execute(args, out, session) -> exit code``."""


def parser() -> argparse.ArgumentParser:
    top = argparse.ArgumentParser(
        prog="coupler", description="Co-simulation of FMUs and gRPC participants from an SSP file."
    )
    top.add_argument("--version", action="version", version=_version())
    top.add_argument("--log-level", default="WARNING", help="DEBUG, INFO, WARNING (default)")
    top.add_argument(
        "--log-format",
        choices=["auto", "console", "json"],
        default="auto",
        help="log lines for people (console) or machines (json); default: console on a "
        "terminal, else json",
    )
    commands = top.add_subparsers(dest="command", required=True)
    for name, module_name in COMMANDS.items():
        module = importlib.import_module(f"coupler_orchestrator.cli.{module_name}")
        description = getattr(module, "DESCRIPTION", None)
        command = commands.add_parser(
            name, help=module.HELP, **({"description": description} if description else {})
        )
        module.arguments(command)
        command.set_defaults(execute=module.execute)
    return top


def _version() -> str:
    """``coupler --version``: the orchestrator's version and the participant SDK's."""
    from importlib.metadata import version

    return (
        f"coupler {version('coupler-orchestrator')} (participant SDK: coupler "
        f"{version('coupler')}; protocol coupler.v1)"
    )


def realtime_factor(text: str) -> float:
    """An argparse type: 0 (as fast as possible) or at least MIN_REALTIME_FACTOR, finite."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
    if value != 0 and not value >= MIN_REALTIME_FACTOR:
        raise argparse.ArgumentTypeError(
            f"must be 0 (as fast as possible) or at least {MIN_REALTIME_FACTOR:g} (one "
            f"simulated second per {1 / MIN_REALTIME_FACTOR:g} s), got {text}"
        )
    return value


def scenario_argument(command: argparse.ArgumentParser) -> None:
    command.add_argument(
        "ssp", type=Path, help=".ssp archive, unpacked SSP folder, .ssd file or a single .fmu"
    )


def run_options(command: argparse.ArgumentParser) -> None:
    command.add_argument("--start-time", type=float, help="start time [s]")
    command.add_argument("--stop-time", type=float, help="stop time [s]")
    command.add_argument("--step", type=float, help="base communication step [s]")
    command.add_argument(
        "--algorithm",
        choices=[a.value for a in Algorithm],
        help="master algorithm (default: the SSD's OpenMCx stepType, sequential = "
        "gauss-seidel, else jacobi)",
    )
    command.add_argument(
        "--openmcx",
        action="store_true",
        help="run with OpenMCx's semantics even when the SSD uses nothing only OpenMCx defines "
        "(docs/openmcx.md)",
    )
    command.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="COMPONENT.NAME=VALUE",
        help="override a parameter or input start value (repeatable; a single FMU's "
        "parameters may be given as NAME=VALUE)",
    )
    command.add_argument(
        "--address",
        action="append",
        default=[],
        metavar="COMPONENT=ADDRESS",
        help="reach COMPONENT's participant at ADDRESS instead of its SSD source, e.g. "
        "Gain=unix:///tmp/gain.sock (repeatable)",
    )
    command.add_argument("--run-id", help="run id sent to participants (default: a random UUID)")
    command.add_argument(
        "--lease",
        type=durations.argument(durations.MAX_LEASE, minimum=durations.MIN_LEASE),
        help="[s] a participant ends the run after this long without a call (default: the "
        "larger of 60 s and 4 call deadlines; at least 1 s, at most 86400 = 24 h)",
    )
    command.add_argument(
        "--connect-timeout",
        type=durations.argument(durations.MAX_TIMEOUT),
        default=10.0,
        help="[s] how long a participant may take to report SERVING (default 10)",
    )
    command.add_argument(
        "--call-timeout",
        type=durations.argument(durations.MAX_TIMEOUT),
        default=30.0,
        help="[s] deadline of every call to a participant (default 30; at most 86400 = 24 h)",
    )
    command.add_argument(
        "--max-message-size",
        type=_message_size,
        default=MAX_MESSAGE_BYTES // 2**20,
        metavar="MiB",
        help="the Binary and String values of one message to or from a participant may have "
        "this many MiB together where its channels declare no maximum, and at most this many "
        f"where they do (default {MAX_MESSAGE_BYTES // 2**20}; at most {MAX_MESSAGE_MIB}); a "
        "larger message fails the run naming its channel",
    )
    command.add_argument(
        "--unpack-limit",
        type=int,
        default=2048,
        metavar="MB",
        help="what an .ssp and the FMUs it runs may unpack to, together (default 2048 MB)",
    )
    command.add_argument(
        "--isolate-fmus",
        action="store_true",
        help="run every FMU in a child process: a crash or hang of an FMU fails the run "
        "cleanly instead of the orchestrator (per component: SSD annotation "
        "org.coupler.component isolate)",
    )
    command.add_argument(
        "--no-native-steps",
        dest="native_steps",
        action="store_false",
        help="step everything through Python: remote participants over grpc.aio instead of the "
        "native step channel (C++ gRPC), in-process FMUs one ctypes call at a time instead of "
        "the native FMU step (C), both from the coupler-native package; the same results "
        "either way (also COUPLER_NATIVE_STEPS=0)",
    )
    command.add_argument(
        "--no-step-socket",
        dest="step_socket",
        action="store_false",
        help="step participants on unix sockets over their StepStream (gRPC) even where they "
        "offer a step socket (docs/protocol.md); the same results either way (also "
        "COUPLER_STEP_SOCKET=0)",
    )
    security_options(command)


def out_options(command: argparse.ArgumentParser, default: str = "results/<scenario>") -> None:
    command.add_argument(
        "--out",
        type=Path,
        metavar="DIR",
        help=f"results folder of this run (default: a new folder {default}/<UTC time>-<run id>/ "
        "per run, `latest` linking to the newest; the SSD's OpenMCx outputDirectory instead of "
        f"{default} when it names one); a folder holding an earlier run's results is refused",
    )
    command.add_argument(
        "--force",
        action="store_true",
        help="--out DIR holds an earlier run's results: replace them (results.csv, "
        "results.parquet, summary.json, recordings/, the frames/ folder of camera channels "
        "and kept-frames/, the frames a run kept, are removed first; nothing else)",
    )


def record_options(command: argparse.ArgumentParser) -> None:
    command.add_argument(
        "--record",
        action="append",
        default=[],
        metavar="COMPONENT[,...]",
        help="record every output of these components at each of their communication points "
        "into OUT/recordings/COMPONENT.crec, for replay (docs/replay.md)",
    )
    replay_option(command)


def replay_option(command: argparse.ArgumentParser) -> None:
    command.add_argument(
        "--replay",
        action="append",
        default=[],
        metavar="COMPONENT=RECORDING",
        help="serve COMPONENT from a recording (a .crec file or a results directory) instead "
        "of its participant (repeatable)",
    )


def security_options(command: argparse.ArgumentParser) -> None:
    group = command.add_argument_group(
        "security of grpcs:// participants (default: COUPLER_TLS_CA, COUPLER_TLS_CERT, "
        "COUPLER_TLS_KEY, COUPLER_TOKEN_FILE; docs/security.md)"
    )
    group.add_argument("--tls-ca", type=Path, help="CA bundle (PEM) trusted for participants")
    group.add_argument("--tls-cert", type=Path, help="client certificate (PEM), mutual TLS")
    group.add_argument("--tls-key", type=Path, help="its private key (PEM)")
    group.add_argument("--token-file", type=Path, help="bearer token sent with every call")


def security_of(args: argparse.Namespace) -> ClientSecurity:
    """The environment's client security with the command line's options on top."""
    from coupler.security import ClientSecurity

    return ClientSecurity.from_environment().override(
        ClientSecurity(
            ca=args.tls_ca, cert=args.tls_cert, key=args.tls_key, token_file=args.token_file
        )
    )


def options_of(args: argparse.Namespace) -> RunOptions:
    """The run's options from ``coupler run`` / ``validate``'s arguments. A run abandoned
    because this process's thread is stuck in a participant ends the process
    (``interrupts.end_abandoned``): a hung in-process FMU cannot be left any other way."""
    from coupler_orchestrator.cli.interrupts import end_abandoned
    from coupler_orchestrator.options import RunOptions

    parameters = {}
    for item in args.param:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise CouplerError(f"--param {item!r}: write COMPONENT.NAME=VALUE")
        parameters[key] = value
    return RunOptions(
        start_time=args.start_time,
        stop_time=args.stop_time,
        step_size=args.step,
        algorithm=Algorithm(args.algorithm) if args.algorithm else None,
        openmcx=args.openmcx or getattr(args, "openmcx_results", False),
        openmcx_results=getattr(args, "openmcx_results", False),
        realtime_factor=getattr(args, "realtime_factor", None) or None,
        parameters=parameters,
        connect_timeout=args.connect_timeout,
        call_timeout=args.call_timeout,
        isolate_fmus=args.isolate_fmus,
        native_steps=args.native_steps,
        step_socket=args.step_socket,
        unpack_limit=args.unpack_limit * 1024 * 1024,
        max_message_bytes=round(args.max_message_size * 2**20),
        lease=args.lease,
        security=security_of(args),
        on_abandoned=end_abandoned,
        output_interval=getattr(args, "output_interval", None),
        output_variables=_listed(getattr(args, "output_variables", ())),
        parquet=getattr(args, "parquet", False),
        record=_listed(getattr(args, "record", ())),
        replays=_replays_of(getattr(args, "replay", ())),
        addresses=_addresses_of(args.address),
        **({"run_id": args.run_id} if args.run_id else {}),
    )


def _listed(items: Sequence[str]) -> tuple[str, ...]:
    """The names of a repeatable option whose values may be comma-separated lists."""
    return tuple(name.strip() for item in items for name in item.split(",") if name.strip())


def _replays_of(items: Sequence[str]) -> dict[str, Path]:
    replays = {}
    for item in items:
        component, sep, path = item.partition("=")
        if not sep or not component or not path:
            raise CouplerError(f"--replay {item!r}: write COMPONENT=RECORDING")
        replays[component] = Path(path)
    return replays


def _addresses_of(items: Sequence[str]) -> dict[str, str]:
    addresses = {}
    for item in items:
        component, sep, address = item.partition("=")
        if not sep or not component or not address:
            raise CouplerError(f"--address {item!r}: write COMPONENT=ADDRESS")
        addresses[component] = address
    return addresses
