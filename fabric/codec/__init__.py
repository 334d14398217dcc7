"""msgpack codec for fabric messages, with validation on the way in.

Three parts, one job each:

- :mod:`fabric.codec.fields`: the field specs a message class's ``SPEC`` is made of (``F``, ``I``, ``S``,
  ``Strs``, ``User``, ``Arr``, ``Msg``, ``Msgs``, ``Opt``, ``Map``), which all offer :class:`Field`, and ``Spec``;
- :mod:`fabric.codec.registry`: which :class:`Message` class each type name stands for (:func:`register`, :func:`registered`,
  :func:`load_plugins`), and the plain views :func:`to_plain` and :func:`messages_equal`;
- :mod:`fabric.codec.wire`: the wire form ``[TYPE, field1, ...]`` with numpy arrays as one msgpack ext,
  :func:`encode` and :func:`decode` (which raises :class:`DecodeError` on anything wrong).

What a message module or a peer needs is importable from here: ``from fabric.codec import encode, decode``.
"""

from fabric.codec.fields import MAX_ITEMS, Arr, F, Field, I, Map, Msg, Msgs, Opt, S, Spec, Strs, User
from fabric.codec.registry import Message, load_plugins, messages_equal, register, registered, to_plain
from fabric.codec.wire import DecodeError, decode, encode

__all__ = [
    "DecodeError",
    "Message",
    "Field",
    "Spec",
    "encode",
    "decode",
    "register",
    "registered",
    "load_plugins",
    "to_plain",
    "messages_equal",
    "F",
    "I",
    "S",
    "Strs",
    "Arr",
    "Msg",
    "Msgs",
    "Opt",
    "Map",
    "User",
    "MAX_ITEMS",
]
