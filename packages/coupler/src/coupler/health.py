"""Health probe for containers and scripts: ``python -m coupler.health grpc://HOST:PORT``.

Exits 0 when the participant's gRPC health service answers SERVING within the timeout
(``--timeout``, default 3 s), 1 otherwise with the reason on stderr. ``grpcs://`` addresses use
the ``COUPLER_TLS_*`` environment variables (docs/security.md); health needs no token.
"""

from __future__ import annotations

import asyncio
import sys

from coupler.client import RemoteParticipant
from coupler.errors import CouplerError
from coupler.security import ClientSecurity


async def probe(address: str, connect_timeout: float = 3.0) -> None:
    """Returns when ``address`` is SERVING; ParticipantUnavailable (or a CouplerError) if not."""
    remote = RemoteParticipant(
        address, connect_timeout=connect_timeout, security=ClientSecurity.from_environment()
    )
    try:
        await remote.wait_until_serving_once()
    finally:
        await remote.close()


def main(argv: list[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    timeout = 3.0
    if len(args) == 3 and args[1] == "--timeout":
        timeout = float(args.pop())
        args.pop()
    if len(args) != 1:
        print("usage: python -m coupler.health grpc://HOST:PORT [--timeout S]", file=sys.stderr)
        return 2
    try:
        asyncio.run(probe(args[0], timeout))
    except CouplerError as exc:
        print(f"not healthy: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
