"""Configuration from environment variables, one prefix per service (pydantic-settings).

Every participant process reads ``ParticipantSettings`` (bind address, port, logging, and the
security of its gRPC server); services subclass it with their own prefix, so the bridge reads
``OPENRAILS_BRIDGE_PORT``, ``OPENRAILS_BRIDGE_TLS_CERT``, ... and command-line options override
them (``add_security_arguments``). The base prefix, ``COUPLER_EXAMPLE_`` (the example
participants), never collides with the orchestrator's client settings (``COUPLER_TLS_CA``, ...).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pydantic_settings import BaseSettings, PydanticBaseSettingsSource, SettingsConfigDict

from coupler.arguments import add_security_arguments, add_socket_argument
from coupler.errors import CouplerError
from coupler.security import ServerSecurity

if TYPE_CHECKING:
    from coupler.participant import Participant
    from coupler.server import ParticipantServer

__all__ = [
    "CommandLineSettings",
    "ParticipantSettings",
    "SecuritySettings",
    "add_security_arguments",
    "add_socket_argument",
    "serve_main",
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


class CommandLineSettings(ParticipantSettings):
    """``ParticipantSettings`` from the command line alone: no environment variable is read
    (``serve_main``'s default, for a participant program that has no prefix of its own)."""

    @classmethod
    def settings_customise_sources(
        cls,
        settings_cls: type[BaseSettings],
        init_settings: PydanticBaseSettingsSource,
        env_settings: PydanticBaseSettingsSource,
        dotenv_settings: PydanticBaseSettingsSource,
        file_secret_settings: PydanticBaseSettingsSource,
    ) -> tuple[PydanticBaseSettingsSource, ...]:
        return (init_settings,)


def serve_main(
    participant: Participant,
    *,
    port: int = 50051,
    description: str | None = None,
    program: str | None = None,
    argv: Sequence[str] | None = None,
    settings: type[ParticipantSettings] = CommandLineSettings,
) -> None:
    """A participant program's main: read the options every Coupler participant takes, serve
    ``participant`` as they say until SIGTERM or SIGINT.

    The options: ``--host``, ``--port`` (default ``port``; 0: any free one), ``--socket PATH``
    (a unix socket instead of TCP, and the step socket beside it: what ``coupler fleet`` passes),
    ``--log-level`` and the security options (``--tls-cert``, ``--tls-key``, ``--tls-client-ca``,
    ``--token-file``, ``--insecure``, ``--reflection``, ``--health-port``; docs/security.md).
    ``settings`` reads what the command line leaves unset (a service's subclass: its
    environment variables). It prints ``serving NAME at ADDRESS`` once serving; a problem it
    cannot serve through (a taken port, a bad certificate, ...) ends the process with one line,
    ``PROGRAM: the problem``, and exit code 1, never a traceback.
    """
    parser = argparse.ArgumentParser(
        prog=program,
        description=description,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--host", help="address to bind (default: 127.0.0.1)")
    parser.add_argument("--port", type=int, help=f"gRPC port, 0 = any free one (default: {port})")
    add_socket_argument(parser)
    parser.add_argument(
        "--log-level", dest="log_level", help="DEBUG, INFO (default), WARNING or ERROR"
    )
    add_security_arguments(parser)
    args = parser.parse_args(argv)
    given: dict[str, Any] = {k: v for k, v in vars(args).items() if v is not None}
    chosen = settings(**given)
    if "port" not in chosen.model_fields_set:
        chosen = chosen.model_copy(update={"port": port})
    from coupler.logs import configure_logging

    configure_logging(chosen.log_level, json=chosen.log_json)

    def announce(server: ParticipantServer) -> None:
        print(f"serving {server.name} at {server.address}", flush=True)

    chosen.serve(participant, program=parser.prog, on_started=announce)
