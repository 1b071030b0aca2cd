"""``coupler run`` against a participant that requires mutual TLS and a token.

    Source (FMI 2) --> Gain (gRPC over grpcs://, mTLS + bearer token) --> Feed (FMI 3) --> Feed2

The same scenario as test_scenarios' mixed run, its Gain reached over TLS: results equal the
plaintext run byte for byte; without the client certificate or the token it is refused before
anything runs.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from coupler.examples.gain import GainParticipant
from coupler.security import ServerSecurity
from coupler.server import ParticipantServer
from coupler_dev.devcerts import DevPki, write_pki

from .support import DATA, Coupler, serving

pytestmark = pytest.mark.usefixtures("fmus")


@pytest.fixture(scope="module")
def pki(tmp_path_factory: pytest.TempPathFactory) -> DevPki:
    return write_pki(tmp_path_factory.mktemp("pki"))


@pytest.fixture
def secure_gain(pki: DevPki, monkeypatch: pytest.MonkeyPatch) -> Iterator[ParticipantServer]:
    security = ServerSecurity(
        cert=pki.server_cert, key=pki.server_key, client_ca=pki.ca, token_file=pki.token
    )
    with serving(GainParticipant(), security) as server:
        monkeypatch.setenv("GAIN_PORT", str(server.port))
        yield server


def secure_ssd(tmp_path: Path) -> Path:
    ssd = tmp_path / "mixed-tls.ssd"
    ssd.write_text((DATA / "mixed.ssd").read_text().replace("grpc://", "grpcs://"))
    return ssd


@pytest.mark.usefixtures("step_path")
def test_mutual_tls_and_token_give_the_plaintext_results(
    coupler: Coupler,
    tmp_path: Path,
    pki: DevPki,
    secure_gain: ParticipantServer,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Over the native step channel and over grpc.aio."""
    secure = coupler(
        "run",
        secure_ssd(tmp_path),
        "--out",
        tmp_path / "tls",
        "--tls-ca",
        pki.ca,
        "--tls-cert",
        pki.client_cert,
        "--tls-key",
        pki.client_key,
        "--token-file",
        pki.token,
    )
    assert secure.code == 0, secure.err
    with serving(GainParticipant()) as plain:
        monkeypatch.setenv("GAIN_PORT", str(plain.port))
        assert coupler("run", DATA / "mixed.ssd", "--out", tmp_path / "plain").code == 0
    tls_csv = (tmp_path / "tls" / "results.csv").read_bytes()
    assert tls_csv == (tmp_path / "plain" / "results.csv").read_bytes()


def test_environment_variables_configure_the_same(
    coupler: Coupler,
    tmp_path: Path,
    pki: DevPki,
    secure_gain: ParticipantServer,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv("COUPLER_TLS_CA", str(pki.ca))
    monkeypatch.setenv("COUPLER_TLS_CERT", str(pki.client_cert))
    monkeypatch.setenv("COUPLER_TLS_KEY", str(pki.client_key))
    monkeypatch.setenv("COUPLER_TOKEN_FILE", str(pki.token))
    outcome = coupler("run", secure_ssd(tmp_path), "--out", tmp_path / "env")
    assert outcome.code == 0, outcome.err


@pytest.mark.parametrize(
    ("leave_out", "message"),
    [
        ("--tls-cert", "requires a client certificate (mutual TLS) and none was given"),
        ("--token-file", "requires a bearer token and the call carried none"),
    ],
)
def test_missing_credentials_are_refused_before_anything_runs(
    coupler: Coupler,
    tmp_path: Path,
    pki: DevPki,
    secure_gain: ParticipantServer,
    leave_out: str,
    message: str,
) -> None:
    options = {
        "--tls-ca": pki.ca,
        "--tls-cert": pki.client_cert,
        "--tls-key": pki.client_key,
        "--token-file": pki.token,
    }
    if leave_out == "--tls-cert":
        del options["--tls-key"]
    del options[leave_out]
    argv = [item for pair in options.items() for item in pair]
    outcome = coupler("run", secure_ssd(tmp_path), "--out", tmp_path / "out", *argv)
    assert outcome.code == 1
    assert message in outcome.err
    assert not (tmp_path / "out" / "results.csv").exists()
