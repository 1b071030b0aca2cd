"""Configuration from environment variables, one prefix per service (pydantic-settings).

Every participant process reads ``ParticipantSettings`` (bind address, port, logging, and the
security of its gRPC server); services subclass it with their own prefix, so the bridge reads
``OPENRAILS_BRIDGE_PORT``, ``OPENRAILS_BRIDGE_TLS_CERT``, ... and command-line options override
them (``add_security_arguments``). The base prefix, ``COUPLER_EXAMPLE_`` (the example
participants), never collides with the orchestrator's client settings (``COUPLER_TLS_CA``, ...).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from pydantic_settings import BaseSettings, SettingsConfigDict

from coupler.arguments import add_security_arguments, add_socket_argument
from coupler.errors import CouplerError
from coupler.security import ServerSecurity

if TYPE_CHECKING:
    from coupler.participant import Participant
    from coupler.server import ParticipantServer

__all__ = [
    "ParticipantSettings",
    "SecuritySettings",
    "add_security_arguments",
    "add_socket_argument",
    "main",
]


class SecuritySettings(BaseSettings):
    """How a participant's gRPC server is secured (docs/security.md)."""

    model_config = SettingsConfigDict(env_prefix="COUPLER_EXAMPLE_", extra="ignore", frozen=True)

    tls_cert: Path | None = None
    """Server certificate chain (PEM); with ``tls_key`` it turns TLS on."""
    tls_key: Path | None = None
    """Private key of ``tls_cert`` (PEM)."""
    tls_client_ca: Path | None = None
    """CA bundle (PEM) that must have signed the clients' certificates (mutual TLS)."""
    token_file: Path | None = None
    """File holding the bearer token every call must carry."""
    insecure: bool = False
    """Allow plaintext gRPC on an interface other than loopback (logged as a warning)."""
    reflection: bool = False
    """Serve gRPC server reflection (for grpcurl); off by default."""
    health_port: int | None = None
    """Also serve the health service alone, plaintext, on this port (for probes that cannot
    do TLS: Kubernetes gRPC probes, Docker healthchecks)."""

    def security(self) -> ServerSecurity:
        return ServerSecurity(
            cert=self.tls_cert,
            key=self.tls_key,
            client_ca=self.tls_client_ca,
            token_file=self.token_file,
            insecure=self.insecure,
            health_port=self.health_port,
        )


class ParticipantSettings(SecuritySettings):
    """What every participant process reads; services subclass it with their own prefix."""

    host: str = "127.0.0.1"
    """Address the gRPC server binds; 0.0.0.0 in containers (with TLS, or ``insecure``)."""
    port: int = 50051
    """gRPC port; 0 picks a free one (printed at start)."""
    socket: Path | None = None
    """Unix socket to serve on instead of ``host:port`` (``unix:///PATH``, same host only)."""
    log_level: str = "INFO"
    """DEBUG, INFO, WARNING or ERROR."""
    log_json: bool | None = None
    """JSON log lines; default: when stderr is not a terminal."""

    def serve(
        self,
        participant: Participant,
        *,
        program: str,
        on_started: Callable[[ParticipantServer], None] | None = None,
    ) -> None:
        """Serve ``participant`` as these settings say (address or unix socket, TLS and token,
        reflection) until SIGTERM or SIGINT: a participant program's main. A CouplerError (a
        taken port, a bad certificate, ...) ends the process with ``PROGRAM: the error``."""
        from coupler.server import run, serve

        try:
            run(
                serve(
                    participant,
                    host=self.host,
                    port=self.port,
                    unix_socket=self.socket,
                    security=self.security(),
                    reflection=self.reflection,
                    on_started=on_started,
                )
            )
        except CouplerError as exc:
            raise SystemExit(f"{program}: {exc}") from exc


def main(
    participant: Participant,
    *,
    name: str | None = None,
    port: int | None = None,
    argv: Sequence[str] | None = None,
    settings: type[ParticipantSettings] = ParticipantSettings,
) -> None:
    """A participant program's whole main: ``main(MyParticipant())`` under ``if __name__ ==
    "__main__"``. It takes every option ``coupler fleet`` passes a participant (``--host``,
    ``--port``, ``--socket`` -- and with it the step socket --, the TLS and token options,
    ``--log-level``; each also from the environment, ``settings``' prefix), configures logging,
    prints ``serving NAME at ADDRESS`` and serves until SIGTERM or Ctrl-C. A problem (a taken
    port, a bad certificate) ends the process with one line, ``NAME: the problem``. ``port``:
    the program's own default port (before ``settings``' default, 50051)."""
    import argparse

    from coupler.logs import configure_logging

    shown = name or type(participant).__name__.removesuffix("Participant") or "participant"
    parser = argparse.ArgumentParser(description=f"Serve {shown} over gRPC (docs/participants.md).")
    parser.add_argument("--host", help="bind address (default 127.0.0.1)")
    parser.add_argument(
        "--port", type=int, help=f"gRPC port; 0 picks a free one (default {port or 50051})"
    )
    add_socket_argument(parser)
    parser.add_argument("--log-level", dest="log_level", help="DEBUG, INFO, WARNING or ERROR")
    add_security_arguments(parser)
    args = parser.parse_args(argv)
    given = {k: v for k, v in vars(args).items() if v is not None}
    if port is not None and "port" not in given:
        given["port"] = port
    chosen = settings(**given)
    configure_logging(chosen.log_level, json=chosen.log_json)

    def announce(server: ParticipantServer) -> None:
        print(f"serving {shown} at {server.address}", flush=True)

    chosen.serve(participant, program=shown, on_started=announce)
