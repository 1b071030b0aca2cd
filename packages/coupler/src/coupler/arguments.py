"""Command-line options shared by participant processes, defined without importing what they
configure (``coupler.settings`` reads them over the environment), so a command's ``--help``
answers at once."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_security_arguments(parser: argparse.ArgumentParser) -> None:
    """``--tls-cert``, ``--tls-key``, ``--tls-client-ca``, ``--token-file``, ``--insecure``,
    ``--reflection``, ``--health-port``; unset options leave the environment's values (dest =
    field names)."""
    group = parser.add_argument_group("security (docs/security.md)")
    group.add_argument("--tls-cert", type=Path, help="server certificate (PEM): serve TLS")
    group.add_argument("--tls-key", type=Path, help="its private key (PEM)")
    group.add_argument(
        "--tls-client-ca", type=Path, help="require client certificates signed by this CA"
    )
    group.add_argument("--token-file", type=Path, help="require this bearer token on every call")
    group.add_argument(
        "--insecure",
        action="store_true",
        default=None,
        help="allow plaintext on a non-loopback address",
    )
    group.add_argument(
        "--reflection", action="store_true", default=None, help="serve gRPC reflection"
    )
    group.add_argument(
        "--health-port",
        type=int,
        help="also serve the health service alone, plaintext, on this port (probes that "
        "cannot do TLS)",
    )


def add_socket_argument(parser: argparse.ArgumentParser) -> None:
    """``--socket PATH``: serve gRPC on a unix socket instead of TCP (same host only; what
    ``coupler fleet`` gives every local participant)."""
    parser.add_argument(
        "--socket",
        type=Path,
        help="serve gRPC on this unix socket instead of TCP (the address is then "
        "unix:///ABSOLUTE/PATH; a stale socket there is replaced, a live one refused)",
    )
