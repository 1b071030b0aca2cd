"""TLS, mutual TLS and bearer tokens between real gRPC servers and clients on loopback.

    RemoteParticipant --grpcs:// (CA, client cert, token)--> ParticipantServer(Gain)

Certificates are made fresh for every test module by ``coupler_dev.devcerts`` (cryptography).
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from coupler.channels import RunSetup
from coupler.client import RemoteParticipant
from coupler.errors import ParticipantError, ParticipantUnavailable, ScenarioError
from coupler.examples.gain import GainParticipant
from coupler.health import probe
from coupler.security import ClientSecurity, ServerSecurity
from coupler.server import ParticipantServer
from coupler.testing import served
from coupler_dev.devcerts import DevPki, write_pki

SETUP = RunSetup(run_id="tls", start_time=0.0, step_size=0.5)


@pytest.fixture(scope="module")
def pki(tmp_path_factory: pytest.TempPathFactory) -> DevPki:
    return write_pki(tmp_path_factory.mktemp("pki"))


@pytest.fixture(scope="module")
def other_pki(tmp_path_factory: pytest.TempPathFactory) -> DevPki:
    """A second, unrelated CA: what an attacker's or a misconfigured side holds."""
    return write_pki(tmp_path_factory.mktemp("other"))


@pytest.fixture
async def mtls_server(pki: DevPki) -> AsyncIterator[ParticipantServer]:
    security = ServerSecurity(
        cert=pki.server_cert, key=pki.server_key, client_ca=pki.ca, token_file=pki.token
    )
    async with served(GainParticipant(), security=security) as server:
        yield server


async def one_step(address: str, security: ClientSecurity) -> float:
    async with RemoteParticipant(address, security=security, connect_timeout=2.0) as remote:
        await remote.initialize(SETUP)
        y = float((await remote.do_step(0.0, 0.5, {"u": 1.5}))["y"])
        await remote.terminate()
    return y


async def test_tls_with_the_right_ca(pki: DevPki) -> None:
    security = ServerSecurity(cert=pki.server_cert, key=pki.server_key)
    async with served(GainParticipant(), security=security) as server:
        assert server.address.startswith("grpcs://127.0.0.1:")
        assert await one_step(server.address, ClientSecurity(ca=pki.ca)) == 3.0


async def test_mutual_tls_and_token_accepted(mtls_server: ParticipantServer, pki: DevPki) -> None:
    security = ClientSecurity(
        ca=pki.ca, cert=pki.client_cert, key=pki.client_key, token_file=pki.token
    )
    assert await one_step(mtls_server.address, security) == 3.0


async def test_a_wrong_ca_is_refused_saying_so(
    mtls_server: ParticipantServer, pki: DevPki, other_pki: DevPki
) -> None:
    security = ClientSecurity(
        ca=other_pki.ca, cert=pki.client_cert, key=pki.client_key, token_file=pki.token
    )
    with pytest.raises(ParticipantUnavailable, match="certificate") as info:
        await one_step(mtls_server.address, security)
    assert "not trusted" in str(info.value)


async def test_a_missing_client_certificate_is_refused_saying_so(
    mtls_server: ParticipantServer, pki: DevPki
) -> None:
    security = ClientSecurity(ca=pki.ca, token_file=pki.token)
    with pytest.raises(ParticipantUnavailable, match="client certificate"):
        await one_step(mtls_server.address, security)


async def test_a_client_certificate_from_another_ca_is_refused(
    mtls_server: ParticipantServer, pki: DevPki, other_pki: DevPki
) -> None:
    security = ClientSecurity(
        ca=pki.ca, cert=other_pki.client_cert, key=other_pki.client_key, token_file=pki.token
    )
    with pytest.raises(ParticipantUnavailable, match="client certificate"):
        await one_step(mtls_server.address, security)


@pytest.mark.parametrize(
    ("token", "message"),
    [
        (None, "requires a bearer token and the call carried none"),
        ("wrong", "the bearer token is wrong"),
    ],
)
async def test_a_missing_or_wrong_token_is_unauthenticated(
    pki: DevPki, tmp_path: Path, token: str | None, message: str
) -> None:
    token_file = None
    if token is not None:
        token_file = tmp_path / "token"
        token_file.write_text(token)
    async with served(GainParticipant(), security=ServerSecurity(token_file=pki.token)) as server:
        await probe(server.address)  # health answers without a token
        with pytest.raises(ParticipantError, match=message) as info:
            await one_step(server.address, ClientSecurity(token_file=token_file))
        assert info.value.status == "UNAUTHENTICATED"
        assert await one_step(server.address, ClientSecurity(token_file=pki.token)) == 3.0


async def test_a_token_is_checked_on_the_step_stream_too(pki: DevPki, tmp_path: Path) -> None:
    """The stream is opened after Initialize: a stolen Initialize does not open it."""
    async with served(GainParticipant(), security=ServerSecurity(token_file=pki.token)) as server:
        assert await one_step(server.address, ClientSecurity(token_file=pki.token)) == 3.0


def test_plaintext_off_loopback_needs_insecure() -> None:
    with pytest.raises(ScenarioError, match=r"refusing to serve plaintext gRPC on 0\.0\.0\.0"):
        ServerSecurity().check("0.0.0.0")
    assert ServerSecurity().check("127.0.0.1") is None
    assert ServerSecurity().check("::1") is None
    warning = ServerSecurity(insecure=True).check("0.0.0.0")
    assert warning is not None and "--insecure" in warning


async def test_a_server_off_loopback_without_tls_does_not_start() -> None:
    server = ParticipantServer(GainParticipant(), host="0.0.0.0", port=0)
    with pytest.raises(ScenarioError, match="pass --insecure"):
        await server.start()


def test_half_a_key_pair_is_an_error(pki: DevPki) -> None:
    with pytest.raises(ScenarioError, match="both a certificate and its key"):
        ServerSecurity(cert=pki.server_cert).check("127.0.0.1")
    with pytest.raises(ScenarioError, match="needs its key"):
        ClientSecurity(cert=pki.client_cert).channel_credentials()


def test_an_unreadable_secret_names_the_file(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match=r"cannot read the token file .*nope"):
        ClientSecurity(token_file=tmp_path / "nope").metadata()


async def test_a_health_port_answers_plaintext_probes_and_nothing_else(pki: DevPki) -> None:
    """Kubernetes gRPC probes and Docker healthchecks cannot do TLS: the health-only port."""
    security = ServerSecurity(
        cert=pki.server_cert,
        key=pki.server_key,
        client_ca=pki.ca,
        token_file=pki.token,
        health_port=0,
    )
    async with served(GainParticipant(), security=security) as server:
        assert server.health_port
        health = f"grpc://127.0.0.1:{server.health_port}"
        await probe(health)  # SERVING, plaintext, no certificate, no token
        with pytest.raises(ParticipantError, match=r"UNIMPLEMENTED|Method not found"):
            async with RemoteParticipant(health, connect_timeout=2.0) as remote:
                await remote.describe()
        await server.stop(grace=0.1)
        with pytest.raises(ParticipantUnavailable):
            await probe(health, connect_timeout=0.5)
