"""The native code of coupler-native, imported from the installed package on first use.

``packages/coupler-native`` compiles the native FMU step (C), the native step channel (C++
gRPC) and the proxy FMU's binaries when its wheel is built; nothing is compiled on the user's
machine, and nothing is loaded from anywhere but that installed package. Without it (a
platform it has no wheel for) every run steps through Python with the same results, and
``coupler export-fmu`` says what to install.
"""

from __future__ import annotations

import importlib
import os
import sys
from typing import Any

import structlog

log = structlog.get_logger("coupler.native")

ENVIRONMENT = "COUPLER_NATIVE_STEPS"
"""``0`` turns native stepping (the native step channel, the native FMU step) off for every run
of the process."""


def switched_on(asked: bool, variable: str) -> bool:
    """Whether ``asked`` and not turned off by the environment ``variable`` (0, no or false)."""
    return asked and os.environ.get(variable, "1").strip().lower() not in ("0", "no", "false")


def wanted(asked: bool = True) -> bool:
    """Whether native stepping is asked for and not turned off by ``COUPLER_NATIVE_STEPS``."""
    return switched_on(asked, ENVIRONMENT)


MISSING = (
    "coupler-native is not installed (its wheel is built for Linux x86_64; in the repository: "
    "make setup)"
)


class NativeModule:
    """A module of coupler-native (``coupler_native.<name>``), imported on the first call; the
    call then gives it, or None when it cannot be had, said once: quietly (logged) when
    coupler-native is not installed, as a warning on stderr when it is installed but does not
    load (a broken installation)."""

    def __init__(self, name: str, what: str) -> None:
        self.name = f"coupler_native.{name}"
        self.what = what
        self._loaded: Any = None
        self.problem: str | None = None
        """Why it cannot be had (None while it can, or before the first call)."""

    def __call__(self) -> Any:
        if self._loaded is not None or self.problem is not None:
            return self._loaded
        try:
            self._loaded = importlib.import_module(self.name)
        except ImportError as exc:
            if isinstance(exc, ModuleNotFoundError) and exc.name == "coupler_native":
                self.problem = MISSING
                log.info("native_module_unavailable", module=self.what, reason=self.problem)
            else:
                self.problem = f"{self.name} does not load: {exc}"
                print(f"warning: {self.what} unavailable: {self.problem}", file=sys.stderr)
        return self._loaded


rows = NativeModule("_rows", "the native CSV row")
"""``rows()``: ``coupler_native._rows`` (``RowFormat`` makes results.csv's lines, ``RowRead``
reads the native FMU step's row from its arrays), or None (why is said once)."""
