"""The registry of message types: which class each type name on the wire stands for, and back.

The built-in types register themselves when :mod:`fabric.interfaces` is imported (on first use of the codec);
third-party packages add theirs with :func:`register` and declare the module in the ``robofabric.messages``
entry point group, which :func:`load_plugins` imports. Also the views of a registered message that do not
depend on the wire: :func:`to_plain` (JSON-ready) and :func:`messages_equal`.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any, ClassVar, Protocol, TypeVar

import numpy as np

if TYPE_CHECKING:
    from fabric.codec.fields import Spec

__all__ = [
    "Message",
    "register",
    "registered",
    "class_named",
    "name_of",
    "ensure_core",
    "load_plugins",
    "to_plain",
    "messages_equal",
]


class Message(Protocol):
    """A message class as the codec sees it: a dataclass whose ``SPEC`` gives each field's spec, in wire order."""

    SPEC: ClassVar[Spec]


_M = TypeVar("_M", bound=Message)

_BY_NAME: dict[str, type[Message]] = {}
_NAME_OF: dict[type, str] = {}


def register(cls: type[_M], name: str | None = None) -> type[_M]:
    """Make a message class known to the codec under ``name`` (default: its class name).

    The class must be a dataclass with a ``SPEC`` mapping each field to a spec.
    Usable as a decorator by packages that add their own message types.
    """
    name = name or cls.__name__
    if not dataclasses.is_dataclass(cls):
        raise TypeError(f"{cls!r} is not a dataclass")
    fields = {f.name for f in dataclasses.fields(cls)}
    spec = getattr(cls, "SPEC", None)
    if not isinstance(spec, dict) or set(spec) != fields:
        raise TypeError(f"{cls.__name__}.SPEC must name exactly its fields {sorted(fields)}")
    other = _BY_NAME.get(name)
    if other is not None and other is not cls and other.__qualname__ != cls.__qualname__:
        raise ValueError(f"message type name {name!r} is already taken by {other!r}")
    _BY_NAME[name] = cls
    _NAME_OF[cls] = name
    return cls


def registered() -> dict[str, type[Message]]:
    ensure_core()
    return dict(_BY_NAME)


def class_named(name: str) -> type[Message] | None:
    """The message class registered under ``name``, or None."""
    return _BY_NAME.get(name)


def name_of(cls: type) -> str | None:
    """The type name ``cls`` travels under, or None for a class that is not registered."""
    return _NAME_OF.get(cls)


def ensure_core() -> None:
    """Register the built-in types, once (importing :mod:`fabric.interfaces` does)."""
    if "JointState" not in _BY_NAME:
        import fabric.interfaces  # noqa: F401  (registers the built-in types)


_plugins_loaded = False


def load_plugins() -> bool:
    """Import the message modules installed packages declare (entry points ``robofabric.messages``), once.

    The built-in types need none: :mod:`fabric.interfaces` registers them when it is imported. The
    entry points are for third-party packages' own types, so that any peer (a viewer, ``echo``, an export) decodes every type on the wire without fabric
    importing the peer packages. Sessions call it when they open, not ``decode``: the imports take a few
    hundred milliseconds, which must not land inside a subscriber callback. Returns whether it loaded now.
    """
    global _plugins_loaded
    if _plugins_loaded:
        return False
    _plugins_loaded = True
    from importlib.metadata import entry_points

    for ep in entry_points(group="robofabric.messages"):
        try:
            ep.load()
        except Exception:  # a broken plugin must not break decoding of everything else
            continue
    return True


def to_plain(msg: Any) -> Any:
    """A JSON-ready view of a message (arrays as lists), for ``echo --json`` and logs."""
    if dataclasses.is_dataclass(msg) and not isinstance(msg, type):
        out: dict[str, Any] = {"type": _NAME_OF.get(type(msg), type(msg).__name__)}
        for f in dataclasses.fields(msg):
            out[f.name] = to_plain(getattr(msg, f.name))
        return out
    if isinstance(msg, np.ndarray):
        return msg.tolist()
    if isinstance(msg, (list, tuple)):
        return [to_plain(x) for x in msg]
    if isinstance(msg, dict):
        return {str(k): to_plain(v) for k, v in msg.items()}
    if isinstance(msg, np.generic):
        return msg.item()
    return msg


def messages_equal(a: Any, b: Any) -> bool:
    """Field-by-field equality that compares arrays exactly (dtype, shape and values)."""
    if type(a) is not type(b):
        return False
    if dataclasses.is_dataclass(a):
        return all(messages_equal(getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(a))
    if isinstance(a, np.ndarray):
        return a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(messages_equal(x, y) for x, y in zip(a, b))
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(messages_equal(a[k], b[k]) for k in a)
    return bool(a == b)
