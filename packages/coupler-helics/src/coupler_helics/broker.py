"""The ``helics_broker`` that the helics wheel ships, started on loopback.

The wheel's ``helics_broker`` console script is a Python wrapper that runs the real binary as
its child; ``command`` names the binary itself, so the process started is the broker (ending
it ends the broker). It binds 127.0.0.1 only (``--local_interface``), on the port given.
"""

from __future__ import annotations

import os


def binary() -> str:
    """The helics_broker binary inside the installed helics wheel."""
    import helics.bin

    return os.path.join(helics.bin.BIN_DIR, "helics_broker")


def command(port: int, federates: int, *, core_type: str = "tcp_ss") -> list[str]:
    """A broker for ``federates`` federates on 127.0.0.1:``port`` (loopback only)."""
    return [
        binary(),
        f"--coretype={core_type}",
        f"--federates={federates}",
        "--local_interface=127.0.0.1",
        f"--port={port}",
        "--loglevel=warning",
    ]
