"""The CPython extension of csrc/step_streams.cc (csrc/step_streams_module.c): the native step
channel (compiled; see coupler_native)."""

from collections.abc import Sequence

from typing_extensions import Buffer

CS_OK: int
CS_FAILED: int
CS_TIMEOUT: int

class Stream:
    """``cs_open``: a remote member's step stream (``host:port``, ``unix:PATH``) or step socket
    (``steps:PATH``); ``error`` says why it did not open (it must still be closed)."""

    def __init__(
        self,
        target: bytes,
        tls: bool,
        roots: bytes,
        key: bytes,
        chain: bytes,
        metadata: Sequence[tuple[str, str]],
        timeout: float,
        max_receive: int,
        max_send: int,
        /,
    ) -> None: ...
    @property
    def error(self) -> str:
        """Why the stream failed (empty while it is fine)."""
    @property
    def failure(self) -> tuple[int, int]:
        """(CS_FAILED or CS_TIMEOUT, the gRPC status code) of the last ``receive`` that gave
        None."""
    def send(self, pieces: Sequence[Buffer], /) -> bool:
        """``cs_send``: the pieces held (not copied) until the next send or ``close``; False
        when the stream has ended or the last answer was not received."""
    def receive(self, timeout: float, /) -> memoryview | None:
        """``cs_receive`` (without the GIL): the answer, valid until the next call; None when
        the stream ended or timed out (``failure``)."""
    def close(self, timeout: float, /) -> int:
        """``cs_close``: how many answers came that no request asked for."""
