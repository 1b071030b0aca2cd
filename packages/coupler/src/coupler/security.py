"""Security of gRPC links: TLS, mutual TLS and bearer tokens, configured from files.

Secrets are never written inline: certificates, keys and tokens are read from files whose
paths come from settings, environment variables, CLI flags or SSD annotations
(docs/security.md). A participant (``ServerSecurity``) may require TLS, client certificates
signed by a CA (mutual TLS) and a bearer token; the orchestrator (``ClientSecurity``) trusts a
CA for ``grpcs://`` addresses, presents its own certificate and sends the token on every call
as ``authorization: Bearer <token>``. Plaintext is for loopback: a participant refuses to bind
another interface without TLS unless told ``insecure``.
"""

from __future__ import annotations

import hmac
import ipaddress
import os
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import grpc

from coupler.errors import ScenarioError

TOKEN_HEADER = "authorization"
"""Metadata key of the bearer token (lower case, as gRPC metadata keys are)."""
OPEN_METHODS = ("/grpc.health.v1.Health/",)
"""Methods answered without a token: health checks must work for probes and compose."""
_MAX_SECRET_BYTES = 1 << 20


def read_secret(path: Path, what: str) -> bytes:
    """The bytes of a certificate, key or token file; ScenarioError naming the file and why."""
    try:
        with path.open("rb") as file:
            data = file.read(_MAX_SECRET_BYTES + 1)
    except OSError as exc:
        raise ScenarioError(f"cannot read the {what} file {path}: {exc.strerror}") from exc
    if len(data) > _MAX_SECRET_BYTES:
        raise ScenarioError(f"the {what} file {path} is larger than 1 MiB; is it the right one?")
    if not data.strip():
        raise ScenarioError(f"the {what} file {path} is empty")
    return data


def read_token(path: Path) -> str:
    """A bearer token: the first line of ``path``, without surrounding white space."""
    token = read_secret(path, "token").decode("utf-8", errors="replace").strip().splitlines()[0]
    if any(c.isspace() for c in token):
        raise ScenarioError(f"the token in {path} contains white space; write one token per file")
    return token


def is_loopback(host: str) -> bool:
    """Whether ``host`` (a name or an address) stays on this machine."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


@dataclass(frozen=True, kw_only=True)
class ServerSecurity:
    """What a participant requires of the clients that call it."""

    cert: Path | None = None
    """Server certificate chain (PEM); with ``key`` it turns TLS on."""
    key: Path | None = None
    """Private key of ``cert`` (PEM)."""
    client_ca: Path | None = None
    """CA bundle (PEM): clients must present a certificate it signed (mutual TLS)."""
    token_file: Path | None = None
    """File holding the bearer token every call must carry."""
    insecure: bool = False
    """Allow plaintext on an interface other than loopback (a warning is logged)."""
    health_port: int | None = None
    """Also serve the health service alone, plaintext, on this port (0 = any free one): for
    probes that cannot do TLS or client certificates (Kubernetes gRPC probes, Docker
    healthchecks). It answers SERVING or NOT_SERVING and nothing else, without a token."""

    @property
    def tls(self) -> bool:
        return self.cert is not None

    def check(self, host: str) -> str | None:
        """ScenarioError for an unusable set-up; a warning text for plaintext off loopback."""
        if (self.cert is None) != (self.key is None):
            raise ScenarioError("TLS needs both a certificate and its key (cert and key files)")
        if self.client_ca is not None and not self.tls:
            raise ScenarioError(
                "mutual TLS (a client CA) needs TLS: give the server certificate and key too"
            )
        if self.tls or is_loopback(host):
            return None
        if not self.insecure:
            raise ScenarioError(
                f"refusing to serve plaintext gRPC on {host}: anyone who reaches that interface "
                f"could drive this participant. Give a TLS certificate and key (docs/security.md) "
                f"or pass --insecure to accept it"
            )
        return f"serving plaintext gRPC on {host} (--insecure): traffic is neither encrypted "
        "nor authenticated by TLS"

    def credentials(self) -> grpc.ServerCredentials | None:
        """Server credentials for TLS, None for plaintext."""
        if self.cert is None or self.key is None:
            return None
        pair = (read_secret(self.key, "TLS key"), read_secret(self.cert, "TLS certificate"))
        roots = read_secret(self.client_ca, "client CA") if self.client_ca else None
        return grpc.ssl_server_credentials(
            [pair], root_certificates=roots, require_client_auth=roots is not None
        )

    def interceptors(self) -> list[grpc.aio.ServerInterceptor]:
        """The token check, when a token is required."""
        if self.token_file is None:
            return []
        return [TokenCheck(read_token(self.token_file))]


class TokenCheck(grpc.aio.ServerInterceptor):
    """Refuses every call but health checks unless it carries the bearer token."""

    def __init__(self, token: str) -> None:
        self._expected = f"Bearer {token}".encode()

    async def intercept_service(
        self,
        continuation: Callable[[grpc.HandlerCallDetails], Awaitable[grpc.RpcMethodHandler]],
        details: grpc.HandlerCallDetails,
    ) -> grpc.RpcMethodHandler:
        handler = await continuation(details)
        method = details.method or ""
        if handler is None or method.startswith(OPEN_METHODS):
            return handler
        given = next((v for k, v in details.invocation_metadata or () if k == TOKEN_HEADER), None)
        if given is not None and hmac.compare_digest(_bytes(given), self._expected):
            return handler
        why = (
            "this participant requires a bearer token and the call carried none (give the "
            "orchestrator --token-file or COUPLER_TOKEN_FILE)"
            if given is None
            else "the bearer token is wrong (check the token file on both sides)"
        )
        return _refusal(handler, grpc.StatusCode.UNAUTHENTICATED, why)


def _bytes(value: str | bytes) -> bytes:
    return value if isinstance(value, bytes) else value.encode()


def _refusal(
    handler: grpc.RpcMethodHandler, code: grpc.StatusCode, message: str
) -> grpc.RpcMethodHandler:
    """A handler of the same shape as ``handler`` that aborts with ``code``."""

    async def abort(request: Any, context: grpc.aio.ServicerContext) -> Any:
        await context.abort(code, message)

    async def abort_stream(request: Any, context: grpc.aio.ServicerContext) -> Any:
        await context.abort(code, message)
        yield  # an async generator, as stream handlers are

    if handler.request_streaming and handler.response_streaming:
        return grpc.stream_stream_rpc_method_handler(abort_stream)
    if handler.request_streaming:
        return grpc.stream_unary_rpc_method_handler(abort)
    if handler.response_streaming:
        return grpc.unary_stream_rpc_method_handler(abort_stream)
    return grpc.unary_unary_rpc_method_handler(abort)


@dataclass(frozen=True, kw_only=True)
class ClientSecurity:
    """What the orchestrator (or any client) presents to participants."""

    ca: Path | None = None
    """CA bundle (PEM) trusted for ``grpcs://`` participants; default: the system's roots."""
    cert: Path | None = None
    """Client certificate chain (PEM) for mutual TLS."""
    key: Path | None = None
    """Private key of ``cert``."""
    token_file: Path | None = None
    """File holding the bearer token sent with every call."""

    @classmethod
    def from_environment(cls, environ: dict[str, str] | None = None) -> ClientSecurity:
        """``COUPLER_TLS_CA``, ``COUPLER_TLS_CERT``, ``COUPLER_TLS_KEY``, ``COUPLER_TOKEN_FILE``."""
        env = os.environ if environ is None else environ

        def path(name: str) -> Path | None:
            value = env.get(name)
            return Path(value) if value else None

        return cls(
            ca=path("COUPLER_TLS_CA"),
            cert=path("COUPLER_TLS_CERT"),
            key=path("COUPLER_TLS_KEY"),
            token_file=path("COUPLER_TOKEN_FILE"),
        )

    def override(self, other: ClientSecurity) -> ClientSecurity:
        """This set-up with every field ``other`` gives replaced."""
        return ClientSecurity(
            ca=other.ca or self.ca,
            cert=other.cert or self.cert,
            key=other.key or self.key,
            token_file=other.token_file or self.token_file,
        )

    def channel_credentials(self) -> grpc.ChannelCredentials:
        """Credentials of a TLS channel (with a client certificate when one is given)."""
        if (self.cert is None) != (self.key is None):
            raise ScenarioError(
                "a client certificate needs its key and the key its certificate (cert and key)"
            )
        return grpc.ssl_channel_credentials(
            root_certificates=read_secret(self.ca, "CA") if self.ca else None,
            private_key=read_secret(self.key, "TLS key") if self.key else None,
            certificate_chain=read_secret(self.cert, "TLS certificate") if self.cert else None,
        )

    def metadata(self) -> tuple[tuple[str, str], ...]:
        """Call metadata: the bearer token, when one is configured."""
        if self.token_file is None:
            return ()
        return ((TOKEN_HEADER, f"Bearer {read_token(self.token_file)}"),)
