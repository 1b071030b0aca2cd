"""A child process that must not outlive its parent (the generic FMU host, the run a
``coupler`` command watches): killed by the kernel when the parent dies, even while its thread
is stuck in C code, where no polling of the parent can run (Linux ``PR_SET_PDEATHSIG``;
elsewhere nothing is set and the child's own checks remain)."""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal

_PR_SET_PDEATHSIG = 1


def die_with_parent(parent: int) -> bool:
    """Ask to be killed (SIGKILL) when the parent process dies; False when ``parent`` (its
    pid, read before this process was started) has died already."""
    with contextlib.suppress(OSError, AttributeError):
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
    return os.getppid() == parent
