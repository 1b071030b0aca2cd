"""TCP ports and unix sockets: who holds one, and a server's refusal to share one.

gRPC servers set SO_REUSEPORT unless told otherwise, so a second server on a taken port starts
without a word and the kernel splits connections between the two processes (a run's calls
then reach two participants). Every server Coupler starts binds without it
(``GRPC_SERVER_OPTIONS``), looks first whether a process listens on the port (``refuse_taken``:
gRPC binding ``localhost`` would otherwise take the one address left free), and turns a failed
bind into ``PortInUse`` naming the port and the process holding it: its pid and command line,
read from /proc (Linux; elsewhere the holder is "a process this user cannot see").

A unix socket path is the same story: gRPC removes whatever file is at the path before it binds,
so a second server would silently take the socket of a live one. ``add_grpc_socket`` refuses a
path where a server answers (naming its process), removes a stale socket (its server is gone),
and refuses a path that is not a socket or does not fit a socket address (107 bytes).
"""

from __future__ import annotations

import contextlib
import errno
import ipaddress
import os
import socket
import stat
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from coupler.errors import PortInUse, ScenarioError

GRPC_SERVER_OPTIONS = (("grpc.so_reuseport", 0),)
"""Options of every gRPC server Coupler starts: a taken port is refused, never shared."""

_WILDCARDS = {ipaddress.ip_address("0.0.0.0"), ipaddress.ip_address("::")}
_Address = ipaddress.IPv4Address | ipaddress.IPv6Address


@dataclass(frozen=True, kw_only=True)
class PortHolder:
    """A process listening on a TCP port."""

    pid: int
    command: str

    def __str__(self) -> str:
        return f"pid {self.pid} ({_short(self.command)})"


def port_is_free(port: int) -> bool:
    """Whether a server could listen on ``port`` on every address (TIME_WAIT does not count,
    as servers set SO_REUSEADDR)."""
    if _listeners(port):
        return False
    with socket.socket() as probe_socket:
        probe_socket.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe_socket.bind(("", port))
        except OSError:
            return False
    return True


def holders_of(port: int, host: str | None = None) -> list[PortHolder]:
    """The processes listening on ``port`` (on an address that overlaps ``host``'s, when
    given), from /proc; empty when they cannot be seen."""
    addresses = _addresses(host)
    inodes = {inode for inode, address in _listeners(port).items() if _overlaps(address, addresses)}
    return _holding({f"socket:[{inode}]" for inode in inodes})


def _holding(wanted: set[str]) -> list[PortHolder]:
    """The processes that have one of the ``wanted`` files (``socket:[INODE]``) open."""
    found: list[PortHolder] = []
    if not wanted:
        return found
    for pid in _pids():
        if not _links(pid) & wanted:
            continue
        try:
            raw = Path(f"/proc/{pid}/cmdline").read_bytes()
        except OSError:
            continue
        found.append(PortHolder(pid=pid, command=raw.replace(b"\0", b" ").decode().strip()))
    return found


def refuse_taken(host: str, port: int, what: str) -> None:
    """PortInUse when a process already listens on ``port`` where ``host`` would bind it."""
    if port == 0:
        return
    addresses = _addresses(host)
    if any(_overlaps(a, addresses) for a in _listeners(port).values()):
        raise in_use(host, port, what)


def in_use(host: str, port: int, what: str) -> PortInUse:
    """The error of a taken port, naming the processes holding it."""
    holders = holders_of(port, host)
    by = ", ".join(map(str, holders)) if holders else "a process this user cannot see"
    return PortInUse(
        f"cannot serve {what} on {_shown(host)}:{port}: the port is in use by {by}; stop that "
        f"process or choose another port",
        port=port,
        holders=holders,
    )


def add_grpc_port(server: Any, host: str, port: int, credentials: Any, what: str) -> int:
    """Bind ``server`` (a grpc.aio server made with ``GRPC_SERVER_OPTIONS``) to host:port, TLS
    with ``credentials`` unless None; PortInUse or ScenarioError naming the address when it
    cannot. Returns the port bound."""
    host = host[1:-1] if host.startswith("[") else host
    refuse_taken(host, port, what)
    bind = host_port(host, port)
    try:
        if credentials is None:
            return int(server.add_insecure_port(bind))
        return int(server.add_secure_port(bind, credentials))
    except RuntimeError as exc:  # grpc says "Failed to bind", not why
        if port and holders_of(port, host):
            raise in_use(host, port, what) from None
        raise ScenarioError(
            f"cannot serve {what} on {_shown(host)}:{port} ({exc}); is the address one of this "
            f"machine's?"
        ) from None


SOCKET_PATH_MAX = 107
"""Longest unix socket path (``sun_path`` holds 108 bytes with the terminating NUL)."""


def add_grpc_socket(server: Any, path: Path, credentials: Any, what: str) -> None:
    """Bind ``server`` to the unix socket ``path`` (TLS with ``credentials`` unless None), mode
    0600 (only its user connects, as to the step socket): a live socket there is refused
    (PortInUse naming its process), a stale one removed first; ScenarioError when the path
    cannot be a socket."""
    path = Path(os.path.abspath(path))
    if len(os.fsencode(path)) > SOCKET_PATH_MAX:
        raise ScenarioError(
            f"cannot serve {what} on unix socket {path}: the path is longer than "
            f"{SOCKET_PATH_MAX} bytes; choose a shorter one"
        )
    if not path.parent.is_dir():
        raise ScenarioError(
            f"cannot serve {what} on unix socket {path}: folder {path.parent} does not exist"
        )
    clear_socket(path, what)
    bind = f"unix:{path}"
    umask = os.umask(0o177)  # the socket file is made 0600 whatever the caller's umask
    try:
        if credentials is None:
            server.add_insecure_port(bind)
        else:
            server.add_secure_port(bind, credentials)
        os.chmod(path, 0o600)
    except RuntimeError as exc:  # grpc says "Failed to bind", not why
        raise ScenarioError(f"cannot serve {what} on unix socket {path} ({exc})") from None
    finally:
        os.umask(umask)


def clear_socket(path: Path, what: str) -> None:
    """Make ``path`` free for a new socket: nothing there, or a stale socket (removed);
    PortInUse when a server answers there, ScenarioError when it is another kind of file."""
    try:
        mode = path.lstat().st_mode
    except FileNotFoundError:
        return
    if not stat.S_ISSOCK(mode):
        raise ScenarioError(
            f"cannot serve {what} on unix socket {path}: a file that is not a socket is there; "
            f"remove it or choose another path"
        )
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as probe_socket:
        try:
            probe_socket.connect(str(path))
        except ConnectionRefusedError:  # nobody listens: a crashed server's leftover
            path.unlink(missing_ok=True)
            return
        except OSError as exc:
            raise ScenarioError(
                f"cannot serve {what} on unix socket {path}: {exc.strerror or exc}"
            ) from None
    holders = socket_holders(path)
    by = ", ".join(map(str, holders)) if holders else "a process this user cannot see"
    raise PortInUse(
        f"cannot serve {what} on unix socket {path}: the socket is in use by {by}; stop that "
        f"process or choose another path",
        port=0,
        holders=holders,
    )


def socket_holders(path: Path) -> list[PortHolder]:
    """The processes listening on the unix socket ``path``, from /proc; empty when they
    cannot be seen."""
    wanted = set()
    with contextlib.suppress(OSError):
        for line in Path("/proc/net/unix").read_text().splitlines()[1:]:
            fields = line.split(maxsplit=7)
            if len(fields) == 8 and fields[7] == str(path) and fields[3] == "00010000":
                wanted.add(f"socket:[{fields[6]}]")
    return _holding(wanted)


@contextlib.contextmanager
def listening(host: str, port: int, what: str) -> Iterator[None]:
    """Around a server's bind (aiohttp's ``TCPSite.start()``): a taken port or an address the
    server cannot use becomes PortInUse or ScenarioError naming it."""
    refuse_taken(host, port, what)
    try:
        yield
    except OSError as exc:
        if exc.errno == errno.EADDRINUSE:
            raise in_use(host, port, what) from None
        raise ScenarioError(
            f"cannot serve {what} on {_shown(host)}:{port}: {exc.strerror or exc}"
        ) from None


def _listeners(port: int) -> dict[str, _Address]:
    """Socket inode -> local address of every socket listening on ``port`` (IPv4 and IPv6),
    from /proc/net/tcp*."""
    found = {}
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        with contextlib.suppress(OSError, ValueError):
            for line in Path(table).read_text().splitlines()[1:]:
                fields = line.split()
                address, _, hex_port = fields[1].rpartition(":")
                if fields[3] == "0A" and int(hex_port, 16) == port:
                    found[fields[9]] = _proc_address(address)
    return found


def _proc_address(text: str) -> _Address:
    """An address as /proc/net/tcp* writes it: 32-bit words in host (little-endian) order."""
    raw = bytes.fromhex(text)
    words = b"".join(raw[i : i + 4][::-1] for i in range(0, len(raw), 4))
    address = ipaddress.ip_address(words)
    if isinstance(address, ipaddress.IPv6Address) and address.ipv4_mapped is not None:
        return address.ipv4_mapped
    return address


def _addresses(host: str | None) -> set[_Address] | None:
    """The addresses ``host`` binds; None for every address (a wildcard, no host, a name that
    does not resolve: the bind itself says)."""
    if not host:
        return None
    try:
        infos = socket.getaddrinfo(host, None, type=socket.SOCK_STREAM)
    except OSError:
        return None
    addresses = set()
    for info in infos:
        address = ipaddress.ip_address(str(info[4][0]).split("%")[0])
        if address in _WILDCARDS:
            return None
        if isinstance(address, ipaddress.IPv6Address) and address.ipv4_mapped is not None:
            address = address.ipv4_mapped
        addresses.add(address)
    return addresses


def _overlaps(listener: _Address, addresses: set[_Address] | None) -> bool:
    return addresses is None or listener in _WILDCARDS or listener in addresses


def _links(pid: int) -> set[str]:
    """What the open files of process ``pid`` are (``socket:[INODE]`` for sockets); a file
    closed while looking (the listing's own, in this process) is skipped."""
    links = set()
    with contextlib.suppress(OSError):
        for fd in os.listdir(f"/proc/{pid}/fd"):
            with contextlib.suppress(OSError):
                links.add(os.readlink(f"/proc/{pid}/fd/{fd}"))
    return links


def _pids() -> Iterator[int]:
    with contextlib.suppress(OSError):
        for entry in os.listdir("/proc"):
            if entry.isdigit():
                yield int(entry)


def host_port(host: str, port: int) -> str:
    """``host:port`` as a URL or a gRPC target writes it: an IPv6 address in brackets
    (``[::1]:8090``)."""
    return f"{_shown(host) if host else host}:{port}"


def _shown(host: str) -> str:
    return f"[{host}]" if ":" in host and not host.startswith("[") else host or "*"


def _short(command: str, limit: int = 80) -> str:
    """``command`` on one line (a ``python -c`` script's newlines as spaces), at most ``limit``
    characters."""
    command = " ".join(command.split())
    return command if len(command) <= limit else command[: limit - 3] + "..."


__all__ = [
    "GRPC_SERVER_OPTIONS",
    "PortHolder",
    "PortInUse",
    "add_grpc_port",
    "add_grpc_socket",
    "clear_socket",
    "holders_of",
    "host_port",
    "in_use",
    "listening",
    "port_is_free",
    "refuse_taken",
    "socket_holders",
]
