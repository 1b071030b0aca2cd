"""What a test can leave running or lying on this machine, read from Linux's /proc and the
kernel's socket table: processes, listening TCP sockets, entries of a folder.

Each reading is cheap enough to take twice per test (one listing of /proc, one netlink dump of
the listening sockets, one listing of a folder); only what is new afterwards is read in detail
(a process's parent, state, command line and environment).
"""

from __future__ import annotations

import contextlib
import os
import socket
import struct
from dataclasses import dataclass
from pathlib import Path

__all__ = [
    "ProcessInfo",
    "environment_value",
    "listening_sockets",
    "process_ids",
    "read_process",
    "socket_inodes",
]


@dataclass(frozen=True)
class ProcessInfo:
    """One process as /proc shows it."""

    pid: int
    ppid: int
    state: str
    """``R``, ``S``, ``D``...; ``Z``: ended, waiting for its parent to read its exit status."""

    @property
    def running(self) -> bool:
        return self.state not in ("Z", "X", "x")

    @property
    def command(self) -> str:
        """The command line that started it (``[name]`` when it has none, e.g. a kernel
        thread, or ``?`` once it is gone)."""
        try:
            with open(f"/proc/{self.pid}/cmdline", "rb") as file:
                raw = file.read()
        except OSError:
            return "?"
        if not raw:
            return f"[{comm(self.pid)}]"
        return " ".join(part.decode(errors="replace") for part in raw.rstrip(b"\0").split(b"\0"))

    def environment(self) -> bytes:
        """Its environment as it was started (``NAME=value`` separated by NUL; empty when it
        cannot be read)."""
        try:
            with open(f"/proc/{self.pid}/environ", "rb") as file:
                return file.read()
        except OSError:
            return b""


def process_ids() -> set[int]:
    """Every process id of this PID namespace (threads not included)."""
    return {int(name) for name in os.listdir("/proc") if name.isdigit()}


def read_process(pid: int) -> ProcessInfo | None:
    """``pid``'s parent and state; None when it has gone."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as file:
            stat = file.read()
    except OSError:
        return None
    fields = stat[stat.rindex(b")") + 2 :].split()  # the name in parentheses may hold spaces
    return ProcessInfo(pid=pid, ppid=int(fields[1]), state=fields[0].decode())


def comm(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/comm").read_text().strip()
    except OSError:
        return "?"


def environment_value(environment: bytes, name: str) -> str | None:
    """``name``'s value in an environment read from /proc (NUL-separated)."""
    prefix = name.encode() + b"="
    for entry in environment.split(b"\0"):
        if entry.startswith(prefix):
            return entry[len(prefix) :].decode(errors="replace")
    return None


# sock_diag (netlink): the kernel lists only the sockets in the asked states, which is cheap
# however many connections the machine has (/proc/net/tcp walks them all: 100 times slower).
_NETLINK_SOCK_DIAG = 4
_SOCK_DIAG_BY_FAMILY = 20
_NLM_F_REQUEST, _NLM_F_DUMP = 0x1, 0x300
_NLMSG_ERROR, _NLMSG_DONE = 2, 3
_TCP_LISTEN = 10


def listening_sockets() -> dict[int, str]:
    """Every listening TCP socket of this network namespace: its inode -> ``address:port``."""
    found: dict[int, str] = {}
    for family in (socket.AF_INET, socket.AF_INET6):
        found.update(_listening(family))
    return found


def _listening(family: int) -> dict[int, str]:
    # struct inet_diag_req_v2: family, protocol, ext, pad, states; inet_diag_sockid (48 bytes)
    request = struct.pack("=BBBBI", family, socket.IPPROTO_TCP, 0, 0, 1 << _TCP_LISTEN)
    request += bytes(48)
    header = struct.pack(
        "=IHHII", 16 + len(request), _SOCK_DIAG_BY_FAMILY, _NLM_F_REQUEST | _NLM_F_DUMP, 1, 0
    )
    found: dict[int, str] = {}
    with socket.socket(socket.AF_NETLINK, socket.SOCK_RAW, _NETLINK_SOCK_DIAG) as netlink:
        netlink.sendto(header + request, (0, 0))
        while True:
            data = netlink.recv(1 << 16)
            offset = 0
            while offset < len(data):
                length, kind = struct.unpack_from("=IH", data, offset)
                if kind == _NLMSG_DONE:
                    return found
                if kind == _NLMSG_ERROR:
                    raise OSError("the kernel refused to list the listening sockets (sock_diag)")
                # struct inet_diag_msg: family, state, timer, retrans; sockid (sport, dport,
                # src[16], dst[16], if, cookie[2]); expires, rqueue, wqueue, uid, inode
                body = offset + 16
                (port,) = struct.unpack_from("!H", data, body + 4)
                source = data[body + 8 : body + 24]
                (inode,) = struct.unpack_from("=I", data, body + 68)
                if family == socket.AF_INET:
                    address = socket.inet_ntop(family, source[:4])
                else:
                    address = f"[{socket.inet_ntop(family, source)}]"
                found[inode] = f"{address}:{port}"
                offset += (length + 3) & ~3


def socket_inodes(pid: int) -> set[int]:
    """The inodes of the sockets ``pid`` holds open (empty when it cannot be read)."""
    inodes: set[int] = set()
    folder = f"/proc/{pid}/fd"
    with contextlib.suppress(OSError):
        for fd in os.listdir(folder):
            with contextlib.suppress(OSError):
                target = os.readlink(f"{folder}/{fd}")
                if target.startswith("socket:["):
                    inodes.add(int(target[8:-1]))
    return inodes
