"""One host of the multi-host test: a fleet's services, kept up until SIGTERM.

    ip netns exec NS python tests/multihost/netns_host.py FLEET.toml ROOT

Starts the fleet file's services with ``coupler_orchestrator.tools.fleet.Fleet`` (health checked
from inside the namespace; ``grpcs://`` health with the ``COUPLER_TLS_*`` environment), prints
``ready`` and waits; SIGTERM or SIGINT stops every service. Exits 1 with the reason when a
service does not become healthy.
"""

from __future__ import annotations

import asyncio
import signal
import sys
from pathlib import Path

from coupler.errors import CouplerError
from coupler.logs import configure_logging
from coupler_orchestrator.tools.fleet import Fleet, FleetSpec


async def serve(fleet_file: Path, root: Path) -> None:
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stop.set)
    async with Fleet(FleetSpec.load(fleet_file, root=root), health_timeout=60):
        print("ready", flush=True)
        await stop.wait()


def main() -> int:
    configure_logging("INFO")  # stderr: stdout carries only "ready"
    try:
        asyncio.run(serve(Path(sys.argv[1]), Path(sys.argv[2])))
    except CouplerError as exc:
        print(f"netns_host: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
