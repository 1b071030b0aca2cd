"""``OpenRailsClient``: OpenRails' web API over ONE aiohttp session, trusting nothing it answers.

Every request has a deadline; every body is read as a stream and refused past
``max_body_bytes`` (without reading the rest), and kept in the pieces it arrived in (a camera
frame's 1.44 MB joined once, where it is used); JSON is parsed straight into the models of
``replies`` (strict types, nesting limited by the parser). Transport errors, timeouts, error
statuses and answers that are too big, not JSON or of the wrong shape become
``ParticipantUnavailable`` naming the URL -- and the field, for a wrong shape -- here and
only here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeVar

import aiohttp
from pydantic import BaseModel, TypeAdapter, ValidationError

from coupler.errors import ParticipantUnavailable

T = TypeVar("T")
SHOWN_PROBLEMS = 3
"""How many of a reply's problems an error message lists."""


@dataclass(frozen=True)
class Answer:
    """An HTTP answer: status and (size-capped) body."""

    status: int
    pieces: tuple[bytes, ...]
    """The body in the pieces aiohttp's parser handed over (joined: ``body``)."""

    @property
    def body(self) -> bytes:
        return self.pieces[0] if len(self.pieces) == 1 else b"".join(self.pieces)

    @property
    def size(self) -> int:
        """Bytes of the body."""
        return sum(map(len, self.pieces))

    @property
    def text(self) -> str:
        return self.body.decode("utf-8", "replace").strip()


class OpenRailsClient:
    """Requests to OpenRails at ``base_url`` on behalf of participant ``participant``."""

    def __init__(
        self,
        base_url: str,
        *,
        participant: str,
        request_timeout_s: float,
        max_body_bytes: int,
        on_unreachable: Callable[[str], None] | None = None,
    ) -> None:
        """``on_unreachable(reason)`` is told when OpenRails cannot be reached at all."""
        self.base_url = base_url
        self.participant = participant
        self.request_timeout_s = request_timeout_s
        self.max_body_bytes = max_body_bytes
        self.on_unreachable = on_unreachable
        self._session: aiohttp.ClientSession | None = None

    async def open(self) -> None:
        if self._session is None:
            timeout = aiohttp.ClientTimeout(total=self.request_timeout_s)
            self._session = aiohttp.ClientSession(timeout=timeout)

    async def close(self) -> None:
        session, self._session = self._session, None
        if session is not None:
            await session.close()

    async def fetch(
        self,
        method: str,
        path: str,
        schema: type[T] | TypeAdapter[T],
        *,
        body: Any = None,
        call: str = "step",
    ) -> T:
        """The answer to ``method path`` as ``schema``; a non-2xx answer is an error."""
        answer = await self.send(method, path, body=body, call=call)
        self.check(answer, method, path, call=call)
        return self.parse(answer, path, schema, call=call)

    def check(self, answer: Answer, method: str, path: str, *, call: str = "step") -> None:
        """ParticipantUnavailable unless ``answer`` is 2xx."""
        if not 200 <= answer.status < 300:
            raise self.error(
                f"OpenRails at {self.base_url}{path} answered {answer.status} to {method}: "
                f"{answer.text[:300] or '(no body)'}",
                call=call,
            )

    def parse(
        self, answer: Answer, path: str, schema: type[T] | TypeAdapter[T], *, call: str = "step"
    ) -> T:
        """``answer``'s JSON body as ``schema``; ParticipantUnavailable naming the field."""
        try:
            if isinstance(schema, TypeAdapter):
                return schema.validate_json(answer.body)
            assert issubclass(schema, BaseModel)
            parsed: T = schema.model_validate_json(answer.body)
            return parsed
        except ValidationError as exc:
            raise self.error(
                f"OpenRails at {self.base_url}{path} answered {answer.status} with a body the "
                f"bridge cannot use: {_problems(exc)}",
                call=call,
            ) from exc

    async def send(
        self,
        method: str,
        path: str,
        *,
        body: Any = None,
        deadline_s: float | None = None,
        call: str = "step",
        limit: tuple[int, str] | None = None,
    ) -> Answer:
        """One request with a deadline and a capped body, whatever its status.

        ``limit``: (cap, why) instead of ``max_body_bytes`` -- a camera frame may be bigger
        than any JSON answer, but no bigger than its declared size. Such a body is buffered
        up to its cap as it arrives: with aiohttp's 64 KiB, reading a 1.44 MB frame paused
        and resumed the socket some twenty times (a system call and a loop turn each)."""
        url = f"{self.base_url}{path}"
        if self._session is None:
            raise self.error(f"not connected to OpenRails at {url}; open() first", call=call)
        total = self.request_timeout_s if deadline_s is None else deadline_s
        try:
            async with self._session.request(
                method,
                url,
                json=body,
                timeout=aiohttp.ClientTimeout(total=total),
                read_bufsize=limit[0] if limit else None,
            ) as response:
                return Answer(response.status, await self._read(response, method, url, call, limit))
        except TimeoutError as exc:
            raise self.error(
                f"OpenRails at {url} did not answer {method} within {total:g} s "
                f"(OPENRAILS_BRIDGE_REQUEST_TIMEOUT_S)",
                call=call,
            ) from exc
        except aiohttp.ClientError as exc:
            reason = f"cannot reach OpenRails at {url}: {type(exc).__name__}: {exc}"
            if self.on_unreachable is not None and isinstance(exc, aiohttp.ClientConnectionError):
                self.on_unreachable(reason)
            raise self.error(reason, call=call) from exc

    async def _read(
        self,
        response: aiohttp.ClientResponse,
        method: str,
        url: str,
        call: str,
        limit: tuple[int, str] | None,
    ) -> tuple[bytes, ...]:
        """The body in pieces, at most ``max_body_bytes`` (or ``limit``): a bigger one is
        refused as soon as it shows, and the connection dropped rather than drained. The pieces
        are those aiohttp's parser made (``iter_chunks``), not joined: ``read()`` would join
        them twice."""
        cap, why = limit or (
            self.max_body_bytes,
            f"the {self.max_body_bytes} bytes the bridge reads (OPENRAILS_BRIDGE_MAX_BODY_BYTES)",
        )
        declared = response.content_length
        pieces: list[bytes] = []
        size = 0
        if declared is None or declared <= cap:  # a declared length is all aiohttp reads
            async for chunk, _ in response.content.iter_chunks():
                pieces.append(chunk)
                size += len(chunk)
                if size > cap:
                    break
            else:
                return tuple(pieces)
        response.close()
        if declared is not None and declared > cap:
            told, refused = f"{declared} bytes, more than", "unread"
        else:
            told, refused = "more than", f"after {size} bytes"
        raise self.error(
            f"OpenRails at {url} answered {method} with {told} {why}; refused {refused}",
            call=call,
        )

    def error(self, message: str, *, call: str = "step") -> ParticipantUnavailable:
        """OpenRails cannot be used: down, slow, or answering what the bridge cannot read."""
        return ParticipantUnavailable(
            message, participant=self.participant, call=call, status="UNAVAILABLE"
        )


def _problems(exc: ValidationError) -> str:
    """The first problems of a validation, each as ``dotted.path: what (got value)``."""
    shown = []
    for error in exc.errors()[:SHOWN_PROBLEMS]:
        where = ".".join(f"[{p}]" if isinstance(p, int) else str(p) for p in error["loc"])
        where = where.replace(".[", "[")
        got = (
            "" if error["type"] in ("missing", "json_invalid") else f" (got {error['input']!r:.60})"
        )
        shown.append(f"{where or 'the body'}: {error['msg']}{got}")
    more = len(exc.errors()) - SHOWN_PROBLEMS
    return "; ".join(shown) + (f"; and {more} more" if more > 0 else "")
