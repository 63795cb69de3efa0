"""Messages of an older camo's bag as the installed types.

A type that gained fields (camo_msgs/StatusArray's colours, say) no longer decodes from an older
bag's bytes with its installed class: the bytes end early. Such a topic's messages are decoded
with the schema the bag holds (mcap_ros2, as Foxglove reads any bag), and their fields copied
into the installed class; what the older type lacks keeps the installed default (empty
columns), and a field whose type changed is left at its default. Render and replay read every
camo bag so.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from mcap.records import Schema
from rclpy.serialization import deserialize_message

from camo_bag.container import TopicInfo
from camo_bag.msgdefs import full_name, message_class, message_definition


def installed(info: TopicInfo) -> bool:
    """The bag holds the installed definition of the topic's type (or says none)."""
    return not info.definition or info.definition == message_definition(full_name(info.type))


def installed_decoder(info: TopicInfo) -> Callable[[bytes], Any]:
    """bytes -> a message of the installed class of the topic's type: directly when the bag's
    schema is the installed one, else through the bag's schema (ValueError if it is unusable)."""
    cls = message_class(info.type)
    if installed(info):
        return lambda data: deserialize_message(data, cls)
    from mcap_ros2.decoder import DecoderFactory

    schema = Schema(id=1, name=info.type, encoding="ros2msg", data=info.definition.encode())
    try:
        decode = DecoderFactory().decoder_for("cdr", schema)
    except Exception as exc:  # noqa: BLE001 - a damaged schema: its parser raises anything
        raise ValueError(f"an unreadable schema: {type(exc).__name__}") from None
    if decode is None:
        raise ValueError("an unreadable schema")
    return lambda data: as_installed(decode(data), cls)


def as_installed(decoded: Any, cls: type) -> Any:
    """A message of `cls` with the fields of `decoded` (an mcap_ros2 message of an older
    definition of that type) that it has, nested messages converted likewise."""
    msg = cls()
    for name, kind in cls.get_fields_and_field_types().items():
        if not hasattr(decoded, name):
            continue
        value = getattr(decoded, name)
        current = getattr(msg, name)
        try:
            if hasattr(current, "get_fields_and_field_types"):  # a nested message
                value = as_installed(value, type(current))
            elif kind.startswith("sequence<") and "/" in kind:  # a sequence of messages
                inner = message_class(kind[len("sequence<") :].split(",")[0].rstrip(">"))
                value = [as_installed(v, inner) for v in value]
            setattr(msg, name, value)
        except (AssertionError, TypeError, ValueError, AttributeError):
            pass  # its type changed: the installed default
    return msg
