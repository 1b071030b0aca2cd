"""What a test can leave in a container engine: containers, networks and volumes, read from the
Docker Engine API on its unix socket (``DOCKER_HOST=unix://...``, else
``/var/run/docker.sock``) with the standard library alone.

Where no engine runs (the socket is absent or does not answer within a moment) there is nothing
to look at, and nothing is read again in that session: the census costs nothing then.
"""

from __future__ import annotations

import http.client
import json
import os
import socket
from dataclasses import dataclass
from typing import Any

__all__ = ["Engine", "EngineObject"]

DEFAULT_SOCKET = "/var/run/docker.sock"
TIMEOUT_S = 5.0
"""One request's limit once the engine has answered the first (a busy engine is slow)."""
PROBE_TIMEOUT_S = 0.5


@dataclass(frozen=True)
class EngineObject:
    """A container, network or volume, as the engine lists it."""

    kind: str
    """``container``, ``network`` or ``volume``."""
    ident: str
    """The engine's id of it: a container's or network's id, a volume's name."""
    name: str
    """For a person and a ``known_leak(engine=...)`` glob: its name (a container's first)."""
    detail: str
    """A container's image, a network's driver, a volume's mount point."""


class _UnixConnection(http.client.HTTPConnection):
    def __init__(self, path: str, timeout: float) -> None:
        super().__init__("localhost", timeout=timeout)
        self.path = path

    def connect(self) -> None:
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.sock.settimeout(self.timeout)
        self.sock.connect(self.path)


# Networks every engine has from its start (never a test's).
_BUILT_IN_NETWORKS = frozenset({"bridge", "host", "none"})


class Engine:
    """The engine's API on its socket."""

    def __init__(self, path: str) -> None:
        self.path = path

    @classmethod
    def find(cls) -> Engine | None:
        """The engine on this machine's socket if it answers, else None."""
        host = os.environ.get("DOCKER_HOST", "")
        if host and not host.startswith("unix://"):
            return None  # an engine over TCP: not this machine's to census
        path = host.removeprefix("unix://") or DEFAULT_SOCKET
        if not os.path.exists(path):
            return None
        engine = cls(path)
        try:
            engine._get("/_ping", timeout=PROBE_TIMEOUT_S)
        except (OSError, ValueError, http.client.HTTPException):
            return None
        return engine

    def objects(self) -> frozenset[EngineObject]:
        """Every container (running or not), network and volume; empty when the engine stopped
        answering (it was stopped: what it held is gone with it)."""
        try:
            containers = self._get("/containers/json?all=1")
            networks = self._get("/networks")
            volumes = self._get("/volumes").get("Volumes") or []
        except (OSError, ValueError, http.client.HTTPException):
            return frozenset()
        found = {
            EngineObject(
                "container",
                c["Id"],
                (c.get("Names") or [c["Id"][:12]])[0].lstrip("/"),
                f"image {c.get('Image', '?')}",
            )
            for c in containers
        }
        found |= {
            EngineObject("network", n["Id"], n["Name"], f"driver {n.get('Driver', '?')}")
            for n in networks
            if n["Name"] not in _BUILT_IN_NETWORKS
        }
        found |= {
            EngineObject("volume", v["Name"], v["Name"], f"at {v.get('Mountpoint', '?')}")
            for v in volumes
        }
        return frozenset(found)

    def _get(self, path: str, timeout: float = TIMEOUT_S) -> Any:
        return self._request("GET", path, timeout=timeout)

    def _request(self, method: str, path: str, timeout: float = TIMEOUT_S) -> Any:
        connection = _UnixConnection(self.path, timeout)
        try:
            connection.request(method, path)
            response = connection.getresponse()
            body = response.read()
        finally:
            connection.close()
        if response.status >= 400 and response.status != 404:
            raise ValueError(f"{method} {path}: HTTP {response.status}")
        return json.loads(body) if body and body[:1] in b"[{" else None
