"""The native code of coupler-native, imported from the installed package on first use: the one
module of the orchestrator that imports ``coupler_native`` (an import-linter contract says so);
the rest asks for ``fmu_steps``, ``step_streams``, ``answers``, ``rows`` or ``proxy_binaries``.

Every native module has a Python twin that does the same where coupler-native is not installed
(or for what C leaves to Python); each pair is one small interface below, chosen once where it
is used, and ``tests/test_twins.py`` runs both of every pair on the same inputs:

    pair                         interface       native             Python twin
    results.csv's line of a row  RowLines        _rows.RowFormat    outputs.csv.RowTemplate
    the FMU step's row           RowReader       _rows.RowRead      native_fmu_step.SlicedRow
    latencies into log buckets   BucketCount     _rows.log_buckets  outputs.latency.log_buckets
    a remote step's answer       AnswerReader    _answers           native_step_channel.
                                                                    ProtobufAnswers

and two whole ways of stepping, compared by results.csv's bytes (master/test_native_steps.py,
master/test_native_kernel.py): a remote member's steps (``coupler.client.StepTransport``:
``_step_streams`` in ``NativeSteps``, or its grpc.aio StepStream) and the in-process FMUs'
(``_fmu_steps`` in ``native_fmu_step.Kernel``, or the master's ``steppers.InProcess``).

``packages/coupler-native`` compiles the native FMU step (C), the native step channel (C++
gRPC) and the proxy FMU's binaries when its wheel is built; nothing is compiled on the user's
machine, and nothing is loaded from anywhere but that installed package. Without it (a
platform it has no wheel for) every run steps through Python with the same results, and
``coupler export-fmu`` says what to install.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from types import ModuleType
from typing import Any, Protocol

import structlog

log = structlog.get_logger("coupler.native")

MISSING = (
    "coupler-native is not installed (its wheel is built for Linux x86_64; in the repository: "
    "make setup)"
)


def _fmu_steps() -> ModuleType:
    from coupler_native import _fmu_steps

    return _fmu_steps


def _step_streams() -> ModuleType:
    from coupler_native import _step_streams

    return _step_streams


def _answers() -> ModuleType:
    from coupler_native import _answers

    return _answers


def _rows() -> ModuleType:
    from coupler_native import _rows

    return _rows


_IMPORTS: dict[str, Callable[[], ModuleType]] = {
    "_fmu_steps": _fmu_steps,
    "_step_streams": _step_streams,
    "_answers": _answers,
    "_rows": _rows,
}
"""How each compiled module is imported (statically, so the import-linter sees every one)."""


class NativeModule:
    """A module of coupler-native (``coupler_native.<name>``), imported on the first call; the
    call then gives it, or None when it cannot be had, said once: quietly (logged) when
    coupler-native is not installed, as a warning on stderr when it is installed but does not
    load (a broken installation)."""

    def __init__(self, name: str, what: str) -> None:
        self.name = f"coupler_native.{name}"
        self.what = what
        self._import = _IMPORTS[name]
        self._loaded: Any = None
        self.problem: str | None = None
        """Why it cannot be had (None while it can, or before the first call)."""

    def __call__(self) -> Any:
        if self._loaded is not None or self.problem is not None:
            return self._loaded
        try:
            self._loaded = self._import()
        except ImportError as exc:
            if isinstance(exc, ModuleNotFoundError) and exc.name == "coupler_native":
                self.problem = MISSING
                log.info("native_module_unavailable", module=self.what, reason=self.problem)
            else:
                self.problem = f"{self.name} does not load: {exc}"
                print(f"warning: {self.what} unavailable: {self.problem}", file=sys.stderr)
        return self._loaded


fmu_steps = NativeModule("_fmu_steps", "the native FMU step")
"""``fmu_steps()``: the native FMU step (``coupler_native._fmu_steps``: ``Members``, ``Log``), or
None (why is said once)."""
step_streams = NativeModule("_step_streams", "the native step channel")
"""``step_streams()``: the native step channel (``coupler_native._step_streams``: ``Stream``),
or None (why is said once)."""
answers = NativeModule("_answers", "the step answers read in C")
"""``answers()``: ``coupler_native._answers``, which reads an answer's outputs from its bytes
as the codec decodes them (else None: protobuf and the codec read every answer)."""
rows = NativeModule("_rows", "the native CSV row")
"""``rows()``: ``coupler_native._rows`` (``RowFormat`` makes results.csv's lines, ``RowRead``
reads the native FMU step's row from its arrays), or None (why is said once)."""


class RowLines(Protocol):
    """results.csv's line of the picked columns of a row (``outputs.csv``)."""

    def line(self, time: float, row: Sequence[Any], /) -> str:
        """``time`` and the picked cells, comma-separated, ending in a newline."""
        ...


class RowReader(Protocol):
    """The native FMU step's results row, read from the arrays its members write."""

    def row(self) -> list[Any]:
        """Every member's outputs now, in the results' column order."""
        ...


class BucketCount(Protocol):
    """Step latencies counted into log buckets (``outputs.latency``)."""

    def __call__(
        self, samples: list[float], floor: float, per_bucket: float, base: float, /
    ) -> tuple[float, float, Mapping[int, int]]:
        """(the samples' total, summed in order, their maximum, {bucket: count}): bucket
        ``int((log(s) - floor) * per_bucket)``, 0 for a sample not above ``base``."""
        ...


class AnswerReader(Protocol):
    """A remote member's step answers read from their bytes (``master.native_step_channel``)."""

    def read(self, data: Any, /) -> tuple[dict[str, Any], float, float] | None:
        """(outputs, step_seconds, waited_seconds) of a serialized DoStepResponse that only
        answers the step (0.0 for a figure it does not say); None for any other (one that
        ends the run, or that protobuf and the codec refuse: the caller reads it again to say
        why)."""
        ...


def proxy_binaries() -> tuple[Path | None, str]:
    """The folder of the proxy FMU's binaries (``CouplerProxy.so`` and the libraries it loads),
    as the installed coupler-native package holds it, or None and why it cannot be had."""
    try:
        import coupler_native
    except ModuleNotFoundError:
        return None, (
            "coupler export-fmu copies the proxy FMU's binaries from the coupler-native "
            "package, which is not installed (its wheel is built for Linux x86_64; in the "
            "repository: make setup)"
        )
    folder: Path = coupler_native.PROXY
    if not (folder / coupler_native.PROXY_BINARY).is_file():
        return None, f"{folder} holds no {coupler_native.PROXY_BINARY}: reinstall coupler-native"
    return folder, ""
