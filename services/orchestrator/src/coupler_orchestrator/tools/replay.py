"""``coupler replay``: a recording served as a gRPC participant (``pipeline.replay``), with the
server security of its options over ``COUPLER_REPLAY_*`` variables."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any, TextIO

from coupler.server import ParticipantServer
from coupler.settings import SecuritySettings
from coupler_orchestrator.pipeline.replay import ReplayParticipant


class ReplaySettings(SecuritySettings):
    """``coupler replay``'s server security: its options over ``COUPLER_REPLAY_*`` variables
    (``COUPLER_REPLAY_TLS_CERT``, ...; docs/security.md)."""

    model_config = SecuritySettings.model_config | {"env_prefix": "COUPLER_REPLAY_"}


async def serve_recording(
    recording: Path,
    component: str | None,
    *,
    host: str,
    port: int,
    given: dict[str, Any],
    out: TextIO,
    unix_socket: Path | None = None,
) -> None:
    """Serve a recording until cancelled; ``given``: the security options set on the command
    line (``ReplaySettings`` fields), over the environment's."""
    participant = ReplayParticipant(recording, component)
    security = ReplaySettings(**given).security()
    server = ParticipantServer(
        participant,
        host=host,
        port=port,
        unix_socket=unix_socket,
        security=security,
        reflection=bool(given.get("reflection")),
    )
    try:
        await server.start()
        print(participant.recording.summary(), file=out)
        print(
            f"serving {participant.recording.component} at {server.address}", file=out, flush=True
        )
        await asyncio.Event().wait()
    finally:
        await server.stop()
