"""A throwaway certificate authority for tests and local fleets:
``python -m coupler_dev.devcerts DIR``.

Writes into DIR: ``ca.pem`` (the CA certificate both sides trust), ``server.pem`` /
``server-key.pem`` (for participants, valid for the names given with ``--name``, default
``localhost`` and ``127.0.0.1``), ``client.pem`` / ``client-key.pem`` (for the orchestrator,
mutual TLS) and ``token`` (a random bearer token). Keys are written readable by their owner
only. For production, use your organisation's CA; see docs/security.md.

Needs the ``cryptography`` package (part of the development environment).
"""

from __future__ import annotations

import argparse
import datetime
import ipaddress
import secrets
from dataclasses import dataclass
from pathlib import Path
from typing import Any

DEFAULT_NAMES = ("localhost", "127.0.0.1")


@dataclass(frozen=True)
class DevPki:
    """Where ``write_pki`` put things."""

    directory: Path
    ca: Path
    server_cert: Path
    server_key: Path
    client_cert: Path
    client_key: Path
    token: Path


def _crypto() -> Any:
    try:
        from cryptography import x509
        from cryptography.hazmat.primitives import hashes, serialization
        from cryptography.hazmat.primitives.asymmetric import ec
        from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID
    except ImportError as exc:  # pragma: no cover - the dev environment has it
        raise SystemExit(
            "coupler_dev.devcerts needs the 'cryptography' package (pip install cryptography)"
        ) from exc
    return x509, hashes, serialization, ec, ExtendedKeyUsageOID, NameOID


def _key() -> Any:
    _, _, _, ec, _, _ = _crypto()
    return ec.generate_private_key(ec.SECP256R1())


def _pem_key(key: Any) -> bytes:
    _, _, serialization, _, _, _ = _crypto()
    return key.private_bytes(
        serialization.Encoding.PEM,
        serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption(),
    )


def _pem_cert(cert: Any) -> bytes:
    _, _, serialization, _, _, _ = _crypto()
    return cert.public_bytes(serialization.Encoding.PEM)


def make_ca(common_name: str = "Coupler development CA") -> tuple[Any, Any]:
    """(certificate, key) of a new self-signed CA valid for 30 days."""
    x509, hashes, _, _, _, NameOID = _crypto()
    key = _key()
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, common_name)])
    now = datetime.datetime.now(datetime.UTC)
    cert = (
        x509.CertificateBuilder()
        .subject_name(name)
        .issuer_name(name)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=30))
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=True,
                key_cert_sign=True,
                crl_sign=True,
                content_commitment=False,
                key_encipherment=False,
                data_encipherment=False,
                key_agreement=False,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .sign(key, hashes.SHA256())
    )
    return cert, key


def issue(
    ca: tuple[Any, Any], common_name: str, *, names: tuple[str, ...] = (), client: bool = False
) -> tuple[Any, Any]:
    """(certificate, key) signed by ``ca`` for a server (``names``) or a client."""
    x509, hashes, _, _, ExtendedKeyUsageOID, NameOID = _crypto()
    ca_cert, ca_key = ca
    key = _key()
    now = datetime.datetime.now(datetime.UTC)
    usage = ExtendedKeyUsageOID.CLIENT_AUTH if client else ExtendedKeyUsageOID.SERVER_AUTH
    builder = (
        x509.CertificateBuilder()
        .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, common_name)]))
        .issuer_name(ca_cert.subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=30))
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(x509.ExtendedKeyUsage([usage]), critical=False)
    )
    if names:
        alternatives: list[Any] = []
        for name in names:
            try:
                alternatives.append(x509.IPAddress(ipaddress.ip_address(name)))
            except ValueError:
                alternatives.append(x509.DNSName(name))
        builder = builder.add_extension(x509.SubjectAlternativeName(alternatives), critical=False)
    return builder.sign(ca_key, hashes.SHA256()), key


def _write(path: Path, data: bytes, *, secret: bool = False) -> Path:
    path.write_bytes(data)
    if secret:
        path.chmod(0o600)
    return path


def write_pki(directory: Path, names: tuple[str, ...] = DEFAULT_NAMES) -> DevPki:
    """A new CA, server and client certificates and a token in ``directory``."""
    directory.mkdir(parents=True, exist_ok=True)
    ca = make_ca()
    server = issue(ca, "coupler participant", names=names)
    client = issue(ca, "coupler orchestrator", client=True)
    return DevPki(
        directory=directory,
        ca=_write(directory / "ca.pem", _pem_cert(ca[0])),
        server_cert=_write(directory / "server.pem", _pem_cert(server[0])),
        server_key=_write(directory / "server-key.pem", _pem_key(server[1]), secret=True),
        client_cert=_write(directory / "client.pem", _pem_cert(client[0])),
        client_key=_write(directory / "client-key.pem", _pem_key(client[1]), secret=True),
        token=_write(directory / "token", secrets.token_urlsafe(32).encode() + b"\n", secret=True),
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m coupler_dev.devcerts", description=__doc__)
    parser.add_argument("directory", type=Path, help="where to write the files")
    parser.add_argument(
        "--name",
        action="append",
        dest="names",
        help="host name or address the participants are reached at (repeatable; default "
        "localhost and 127.0.0.1)",
    )
    args = parser.parse_args(argv)
    pki = write_pki(args.directory, tuple(args.names or DEFAULT_NAMES))
    print(f"wrote a development CA, server and client certificates and a token to {pki.directory}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
