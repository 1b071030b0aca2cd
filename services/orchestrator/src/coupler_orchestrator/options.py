"""What the user may set on top of a scenario: the options of ``coupler run`` and ``validate``.

Every stage of the pipeline reads the part it needs; none of them changes it.
"""

from __future__ import annotations

import os
import secrets
import uuid
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

from coupler.archives import DEFAULT_BUDGET_BYTES
from coupler.errors import ScenarioError
from coupler.security import ClientSecurity
from coupler.values import MAX_MESSAGE_BYTES
from coupler.wire import MAX_SECRET, MIN_SECRET, SECRET_BYTES
from coupler_orchestrator.model import Algorithm
from coupler_orchestrator.observer import RunEnd

SECRET_VARIABLE = "COUPLER_RUN_SECRET"
NATIVE_STEPS_VARIABLE = "COUPLER_NATIVE_STEPS"
"""``0`` (or no, false) turns native stepping off for every run of the process, as
``--no-native-steps`` does (``RunOptions.switched``)."""
STEP_SOCKET_VARIABLE = "COUPLER_STEP_SOCKET"
"""``0`` (or no, false) keeps remote participants off their step sockets, as
``--no-step-socket`` does (``RunOptions.switched``)."""
"""A run secret chosen from outside (UTF-8, at least 16 bytes); unset: a random one."""


def run_secret() -> bytes:
    """A new run's secret: ``COUPLER_RUN_SECRET`` when set, else 32 bytes from the system's
    CSPRNG (``secrets``)."""
    chosen = os.environ.get(SECRET_VARIABLE)
    if chosen is None:
        return secrets.token_bytes(SECRET_BYTES)
    secret = chosen.encode()
    if not MIN_SECRET <= len(secret) <= MAX_SECRET:
        raise ScenarioError(
            f"{SECRET_VARIABLE} must be {MIN_SECRET} to {MAX_SECRET} bytes, it has "
            f"{len(secret)}; unset it to get a random secret per run"
        )
    return secret


@dataclass(frozen=True, kw_only=True)
class RunOptions:
    """Options of one run (the CLI flags of ``coupler run``)."""

    start_time: float | None = None
    """Overrides DefaultExperiment startTime [s]; default 0."""
    stop_time: float | None = None
    """Overrides DefaultExperiment stopTime [s]."""
    step_size: float | None = None
    """Base communication step [s]; default the OpenMCx task deltaTime."""
    algorithm: Algorithm | None = None
    """Master algorithm; default from the OpenMCx task stepType, else Jacobi."""
    openmcx: bool = False
    """Run with OpenMCx's semantics even when the scenario uses nothing only OpenMCx defines
    (docs/openmcx.md)."""
    openmcx_results: bool = False
    """Also write OpenMCx's result files (``<Component>_res.csv``, ``<Component>_in.csv``)."""
    realtime_factor: float | None = None
    """Pace the run (the command line takes at least ``cli.parser.MIN_REALTIME_FACTOR``); None
    runs as fast as possible."""
    parameters: Mapping[str, str] = field(default_factory=dict)
    """``Component.name`` -> value text, overriding the SSD's parameter bindings."""
    run_id: str = field(default_factory=lambda: uuid.uuid4().hex)
    """Identifies the run; a random UUID unless given. Public: files, logs and the monitor
    show it."""
    run_secret: bytes = field(default_factory=lambda: run_secret(), repr=False)
    """Authenticates every call of the run at its participants: 32 random bytes, or the
    ``COUPLER_RUN_SECRET`` environment variable's (never a flag: command lines are public).
    Never written to a file or a log."""
    lease: float | None = None
    """Lease of the run at each participant [s]; default: well above the call deadline and the
    pacing (``plan.lease_of``)."""
    connect_timeout: float = 10.0
    """How long a remote participant may take to report SERVING [s]."""
    call_timeout: float = 30.0
    """Deadline of each call to a participant [s]; per component: the SSD annotation
    ``org.coupler.component callTimeout``."""
    native_steps: bool = True
    """Step natively: remote participants over the native step channel (C++ gRPC on the
    master's thread, built once per machine when the tool chain is installed, ``steps``), a
    run of in-process FMUs in C (``kernel``). False, or with ``COUPLER_NATIVE_STEPS=0``:
    Python's grpc.aio and one ctypes call per FMI call, with the same results."""
    step_socket: bool = True
    """Step a remote participant reached over ``unix://`` that offers a step socket
    (docs/protocol.md "Step socket") over it, natively and without gRPC. False, or with
    ``COUPLER_STEP_SOCKET=0``: over its StepStream, with the same results."""
    progress: memoryview | None = field(default=None, compare=False, repr=False)
    """Three doubles in memory that outlives this process (the supervisor's shared page): the
    native FMU step keeps the step under way there (member slot, since, time), so a crash in C
    still says how far the run got (``cli.supervisor``)."""
    on_abandoned: Callable[[RunEnd], None] | None = field(default=None, compare=False)
    """Called on the watchdog's thread when the run is abandoned because the master's thread
    is stuck in a participant (an in-process FMU hanging past its deadline, or through an
    interrupt), after every observer was told how it ended. The command line ends the process
    there, the only way out of a thread stuck in C; a library caller that gives nothing keeps
    its process and is told the run failed (or was aborted)."""
    max_message_bytes: int = MAX_MESSAGE_BYTES
    """The Binary and String values of one message to or from a remote participant may have
    this many bytes together where its channels declare no maximum (``Channel.max_bytes``),
    and at most this many where they do (the sum of their maxima, else); more fails the run
    naming the channel (docs/protocol.md "Message size")."""
    unpack_limit: int = DEFAULT_BUDGET_BYTES
    """Bytes an .ssp and the FMUs it runs may unpack to, together (zip bombs)."""
    isolate_fmus: bool = False
    """Run every FMU in a child process (per component: ``org.coupler.component isolate``)."""
    output_interval: float | None = None
    """Record every communication point that is a whole multiple of this past t_0 [s]; None:
    every one. Must be a multiple of the step."""
    output_variables: tuple[str, ...] = ()
    """Columns recorded: names or globs (``Gain.*``); empty: every output."""
    parquet: bool = False
    """Also write results.parquet (needs the pyarrow package)."""
    record: tuple[str, ...] = ()
    """Components whose outputs are recorded to ``recordings/COMPONENT.crec`` in the results
    directory (docs/replay.md)."""
    replays: Mapping[str, Path] = field(default_factory=dict)
    """Component -> recording (a .crec file or a results directory) served in its place."""
    addresses: Mapping[str, str] = field(default_factory=dict)
    """Where remote participants really are: a component's name, or an address as the SSD's
    sources expand to (``grpc://127.0.0.1:50061``), -> the address to use instead
    (``unix:///PATH``: ``coupler fleet`` serves its local participants on unix sockets)."""
    security: ClientSecurity = field(default_factory=ClientSecurity.from_environment)
    """TLS trust, client certificate and token for every remote participant (default: the
    ``COUPLER_TLS_*`` and ``COUPLER_TOKEN_FILE`` environment variables)."""
    on_waiting: Callable[[str, str, str], None] | None = field(default=None, compare=False)
    """Called once per remote participant that is not SERVING at the first check, with its
    component name, address and the reason (e.g. "connection refused: ..."), so a person
    sees at once what the run waits for."""

    def switched(self, environ: Mapping[str, str] | None = None) -> RunOptions:
        """These options with the environment's switches applied (``COUPLER_NATIVE_STEPS``,
        ``COUPLER_STEP_SOCKET``): the one place they are read; every later stage takes
        ``native_steps`` and ``step_socket`` as they are here."""
        env = os.environ if environ is None else environ

        def on(variable: str) -> bool:
            return env.get(variable, "1").strip().lower() not in ("0", "no", "false")

        return replace(
            self,
            native_steps=self.native_steps and on(NATIVE_STEPS_VARIABLE),
            step_socket=self.step_socket and on(STEP_SOCKET_VARIABLE),
        )
