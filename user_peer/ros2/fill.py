"""Fill an ``rclpy`` message from the plain dict of its fields that the MCAP export's conversion makes.

:func:`user_peer.openfmt.ros2.ros2_message` gives ``(type name, dict)``; the MCAP writer serialises the dict
as CDR, and the bridge fills a live message with it here, so both carry the same values. Needs ``rclpy``'s
message packages (imported by type name, e.g. ``sensor_msgs/msg/JointState`` -> ``sensor_msgs.msg``).
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = ["message_class", "fill"]

_classes: dict[str, type] = {}


def message_class(type_name: str) -> type:
    """The ``rclpy`` message class of ``pkg/msg/Name`` (``ImportError`` when its package is not installed)."""
    cls = _classes.get(type_name)
    if cls is None:
        pkg, sub, name = type_name.split("/")
        cls = _classes[type_name] = getattr(importlib.import_module(f"{pkg}.{sub}"), name)
    return cls


def _element_class(msg: Any, field: str) -> type | None:
    """The message class of the elements of sequence field ``field`` of ``msg``, or None for plain values."""
    slot = dict(zip(msg.__slots__, msg.SLOT_TYPES)).get(f"_{field}")
    value_type = getattr(slot, "value_type", None)
    namespaces = getattr(value_type, "namespaces", None)
    if not namespaces:
        return None
    return message_class("/".join([*namespaces, value_type.name]))


def fill(msg: Any, fields: dict) -> Any:
    """Set ``msg``'s fields from ``fields`` (nested dicts for nested messages, lists of dicts for sequences of
    messages); returns ``msg``. A field the message does not have is an ``AttributeError``."""
    for name, value in fields.items():
        if isinstance(value, dict):
            fill(getattr(msg, name), value)
        elif isinstance(value, list) and value and isinstance(value[0], dict):
            cls = _element_class(msg, name)
            if cls is None:
                raise AttributeError(f"{type(msg).__name__}.{name} is not a sequence of messages")
            setattr(msg, name, [fill(cls(), v) for v in value])
        else:
            setattr(msg, name, value)
    return msg
