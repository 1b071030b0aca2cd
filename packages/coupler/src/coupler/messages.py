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
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

from google.protobuf import json_format
from google.protobuf.message import DecodeError, Message

from coupler.errors import ChannelValueError

ENTRY_POINTS = "coupler.messages"
"""The entry point group installed packages name their message types in."""

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
