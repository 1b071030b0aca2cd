"""A TCP relay that holds every byte back for a fixed time in each direction: network latency
for the multi-host test on kernels built without ``sch_netem``.

    python tests/multihost/delay_relay.py --one-way-ms 5 LISTEN_HOST:PORT=TARGET_HOST:PORT ...

Each chunk read is written on at its arrival time plus the delay, in order, so a round trip
through the relay takes twice the delay longer while throughput is untouched (as with
``tc qdisc ... netem delay``). TLS passes through untouched: the relay only sees ciphertext.
Prints ``ready`` once every listener is bound; SIGTERM ends it.

The relay stands for a network, which does not wait for a CPU: it asks for real-time
scheduling (SCHED_FIFO, root only) so that a machine busy with the simulation does not add
scheduling delays to the link (the kernel forwards packets without waiting, too).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import queue
import socket
import threading
import time


def _endpoint(text: str) -> tuple[str, int]:
    host, _, port = text.rpartition(":")
    return host, int(port)


def pump(source: socket.socket, target: socket.socket, delay: float) -> None:
    """Copy ``source`` to ``target``, each chunk ``delay`` seconds after it arrived."""
    chunks: queue.SimpleQueue[tuple[float, bytes]] = queue.SimpleQueue()

    def read() -> None:
        with contextlib.suppress(OSError):
            while data := source.recv(65536):
                chunks.put((time.monotonic() + delay, data))
        chunks.put((0.0, b""))

    def write() -> None:
        while True:
            due, data = chunks.get()
            if not data:
                break
            time.sleep(max(0.0, due - time.monotonic()))
            try:
                target.sendall(data)
            except OSError:
                break
        with contextlib.suppress(OSError):
            target.shutdown(socket.SHUT_WR)

    threading.Thread(target=read, daemon=True).start()
    threading.Thread(target=write, daemon=True).start()


def relay(listen: tuple[str, int], target: tuple[str, int], delay: float) -> None:
    """Accept on ``listen`` in a thread; each connection gets its own link to ``target``."""
    server = socket.create_server(listen)

    def accept() -> None:
        while True:
            client, _ = server.accept()
            try:
                upstream = socket.create_connection(target, timeout=5)
            except OSError:
                client.close()
                continue
            upstream.settimeout(None)
            for end in (client, upstream):
                end.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            pump(client, upstream, delay)
            pump(upstream, client, delay)

    threading.Thread(target=accept, daemon=True).start()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--one-way-ms", type=float, required=True, help="delay each way [ms]")
    parser.add_argument("routes", nargs="+", metavar="LISTEN_HOST:PORT=TARGET_HOST:PORT")
    args = parser.parse_args()
    with contextlib.suppress(OSError):  # not root: ordinary scheduling, a noisier link
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(10))
    for route in args.routes:
        listen, _, target = route.partition("=")
        relay(_endpoint(listen), _endpoint(target), args.one_way_ms / 1000)
    print("ready", flush=True)
    threading.Event().wait()


if __name__ == "__main__":
    main()
