"""Structured values in binary channels: protobuf messages known by their full name.

A binary channel may carry a serialized protobuf message; its description names the message
(``Channel.message_type``, e.g. ``coupler.v1.TrainState``). Domain packages register the
messages they define (``register(TrainState)``, done by ``coupler_railway.messages`` for the
railway messages); the core knows no domain. Registered messages can be built from and read
into plain dicts, and shown as JSON text in results.

Installed packages are found without being imported by anyone: a package names its messages'
module in the entry point group ``coupler.messages`` (``pyproject.toml``)::

    [project.entry-points."coupler.messages"]
    railway = "coupler_railway.messages"     # a module that calls register(...) when imported

and the first time a message type is not known, every such entry point is loaded (once per
process). A module, a message class or a sequence of message classes may be named.

A message with one long bytes field (a camera frame's pixels) can be written and read without
that field passing through protobuf, which copies such a value into the message and out again
and was slow at it (``with_bytes``, ``without_bytes``): its encoding lets a message be its other
fields followed by the field's key, length and bytes.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any, TypeVar

from google.protobuf import json_format
from google.protobuf.message import DecodeError, Message

from coupler.errors import ChannelValueError
from coupler.wire import _fields, _varint

ENTRY_POINTS = "coupler.messages"
"""The entry point group installed packages name their message types in."""

M = TypeVar("M", bound=Message)
_LEN = 2
"""The wire type of a length-delimited field."""
_REGISTRY: dict[str, type[Message]] = {}
_installed: list[str] | None = None
"""The entry points loaded so far (None: not looked for yet)."""


def register(*classes: type[Message]) -> None:
    """Make messages known by their full name (``Class.DESCRIPTOR.full_name``)."""
    for cls in classes:
        _REGISTRY[cls.DESCRIPTOR.full_name] = cls


def load_installed() -> tuple[str, ...]:
    """Load the message types installed packages declare (entry point group
    ``coupler.messages``), once per process; the entry points loaded. One that fails to load is
    logged and skipped: it cannot take the others down."""
    global _installed
    if _installed is not None:
        return tuple(_installed)
    _installed = []
    from importlib.metadata import entry_points

    for entry in entry_points(group=ENTRY_POINTS):
        try:
            found = entry.load()
        except Exception as exc:
            import structlog

            structlog.get_logger("coupler.messages").warning(
                "message_types_not_loaded", entry_point=entry.value, error=repr(exc)
            )
            continue
        if isinstance(found, type) and issubclass(found, Message):
            register(found)
        elif isinstance(found, (list, tuple)):
            register(*(c for c in found if isinstance(c, type) and issubclass(c, Message)))
        _installed.append(f"{entry.name} = {entry.value}")
    return tuple(_installed)


def known(message_type: str) -> bool:
    """Whether ``message_type`` is registered (or declared by an installed package)."""
    if message_type not in _REGISTRY:
        load_installed()
    return message_type in _REGISTRY


def registered() -> tuple[str, ...]:
    """The full names of every registered message (installed packages' included), sorted."""
    load_installed()
    return tuple(sorted(_REGISTRY))


def message_class(message_type: str) -> type[Message]:
    """The class registered for ``message_type``; ChannelValueError listing the known ones."""
    if message_type not in _REGISTRY:
        load_installed()
    cls = _REGISTRY.get(message_type)
    if cls is None:
        raise ChannelValueError(
            f"unknown protobuf message type '{message_type}' (registered: "
            f"{', '.join(registered()) or 'none'}); install the package that defines it "
            f"(entry point group '{ENTRY_POINTS}') or import the module that registers it",
            channel="",
            expected=message_type,
        )
    return cls


def encode_message(message_type: str, fields: Mapping[str, Any]) -> bytes:
    """Serialize the message ``message_type`` built from ``fields`` (proto field names)."""
    message = message_class(message_type)()
    try:
        json_format.ParseDict(dict(fields), message)
    except json_format.ParseError as exc:
        raise ChannelValueError(
            f"fields do not fit {message_type}: {exc}", channel="", expected=message_type
        ) from exc
    return message.SerializeToString(deterministic=True)


def decode_message(message_type: str, data: bytes) -> dict[str, Any]:
    """The fields of a serialized ``message_type`` (proto field names, every field present)."""
    message = message_class(message_type)()
    try:
        message.ParseFromString(data)
    except DecodeError as exc:
        raise ChannelValueError(
            f"bytes are not a valid {message_type}: {exc}", channel="", expected=message_type
        ) from exc
    return json_format.MessageToDict(
        message, preserving_proto_field_name=True, always_print_fields_with_no_presence=True
    )


def message_json(message_type: str, data: bytes) -> str:
    """A serialized message as compact JSON text (keys in field order), for results files."""
    return json.dumps(decode_message(message_type, data), separators=(",", ":"), ensure_ascii=False)


def with_bytes(message: Message, field: str, *data: bytes) -> bytes:
    """``message`` serialized with its bytes field ``field`` set to ``data`` (the value, in one
    or more pieces), without ``data`` passing through protobuf: the message as it is (``field``
    unset) serialized, then the field's key, length and the pieces, joined once. The same bytes
    as protobuf's deterministic serialization when ``field`` has the highest number of the
    fields set (as ``data`` in ``coupler.v1.Image``); a valid encoding of the same message
    otherwise."""
    head = message.SerializeToString(deterministic=True)
    size = sum(map(len, data))
    if not size:  # proto3 writes no empty bytes field
        return head
    number = message.DESCRIPTOR.fields_by_name[field].number
    return b"".join([head, _varint(number << 3 | _LEN), _varint(size), *data])


def without_bytes(cls: type[M], data: bytes, field: str) -> tuple[M, memoryview]:
    """The message ``cls`` serialized in ``data``, parsed without its bytes field ``field``,
    and that field's value as a view of ``data`` (not copied; empty when unset). Bytes that
    are not as expected are left whole to protobuf, which parses them or raises its
    ``DecodeError``."""
    view = memoryview(data)
    key = cls.DESCRIPTOR.fields_by_name[field].number << 3 | _LEN
    try:
        rest, value = _split(view, key)
    except (IndexError, ValueError):
        message = cls.FromString(bytes(view))
        value = memoryview(getattr(message, field))
        message.ClearField(field)
        return message, value
    return cls.FromString(rest), value


def _split(data: memoryview, field: int) -> tuple[bytes, memoryview]:
    """``data`` without the top-level field of key ``field`` (a length-delimited one), and
    the last value of that field (protobuf's rule for a field written twice)."""
    kept: list[memoryview] = []
    value = data[0:0]
    start = 0
    for key, at, body, after in _fields(data):
        if key >> 3 == field >> 3:
            if key != field:
                raise ValueError("the field with another wire type")
            kept.append(data[start:at])
            value = data[body:after]
            start = after
    kept.append(data[start:])
    return b"".join(kept), value
