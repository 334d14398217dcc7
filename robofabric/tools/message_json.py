"""A message of any installed type from the JSON of its fields (``pub --data``, ``call --data``), wrong input said in words."""

from __future__ import annotations

import json

from fabric.cli_common import UserError

__all__ = ["message_from_json"]


def message_from_json(msg_type: str, data: str):
    """A message of any installed type (plugins included) from a JSON object of its fields.

    What is wrong is said in words, naming the field (``Twist needs field 'omega' (a number)``), never as
    Python's ``Twist.__init__() missing 1 required positional argument``; the message is checked as a
    receiver would decode it, so nothing the sim would refuse as undecodable leaves."""
    from fabric.codec import DecodeError, decode, encode, load_plugins, registered

    load_plugins()
    types = registered()
    cls = types.get(msg_type)
    if cls is None:
        raise UserError(f"unknown message type {msg_type!r}; known: {', '.join(sorted(types))}")
    try:
        fields = json.loads(data)
    except ValueError as exc:
        raise UserError(f"--data is not JSON: {exc}") from None
    if not isinstance(fields, dict):
        raise UserError(f"--data must be a JSON object of {msg_type}'s fields ({_fields_words(cls)}), got {data!r}")
    fields = _checked_fields(cls, fields)
    try:
        msg = cls(**fields)
        decode(encode(msg), cls)  # as the receiver will: finiteness, ranges, shapes
    except DecodeError as exc:
        raise UserError(f"bad {msg_type}: {exc}") from None
    except (ValueError, TypeError) as exc:
        raise UserError(f"cannot build {msg_type} from {data!r}: {exc}") from None
    return msg


def _spec_words(spec) -> str:
    """What a field's codec spec asks for, in words."""
    name = type(spec).__name__
    if name == "F":
        bounds = f" in [{spec.lo}, {spec.hi}]" if spec.lo is not None or spec.hi is not None else ""
        return f"a number{bounds}"
    if name == "I":
        return "an integer"
    if name in ("S", "User"):
        return "a string"
    if name == "Strs":
        return "a list of strings"
    if name == "Arr":
        return "a list of numbers" if getattr(spec, "ndim", None) in (None, 1) else f"a {spec.ndim}-D array of numbers"
    return "a value"


def _fields_words(cls) -> str:
    import dataclasses

    spec = getattr(cls, "SPEC", {})
    return ", ".join(
        f"{f.name}: {_spec_words(spec.get(f.name))}" for f in dataclasses.fields(cls) if f.name != "header"
    )


def _checked_fields(cls, fields: dict) -> dict:
    """``fields`` for ``cls``, each checked against its spec; a missing, unknown or bad one is a :class:`UserError`
    naming it."""
    import dataclasses

    import numpy as np

    from fabric.codec import DecodeError

    name = cls.__name__
    known = {f.name: f for f in dataclasses.fields(cls)}
    spec = getattr(cls, "SPEC", {})
    for k in fields:
        if k not in known:
            raise UserError(f"{name} has no field {k!r}; its fields: {_fields_words(cls)}")
    for k, f in known.items():
        if k not in fields and f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise UserError(f"{name} needs field {k!r} ({_spec_words(spec.get(k))}); its fields: {_fields_words(cls)}")
    out = dict(fields)
    for k, v in fields.items():
        s = spec.get(k)
        kind = type(s).__name__
        if kind not in ("F", "I", "S", "Strs", "Arr"):
            continue  # nested messages and maps: the constructor and the codec say what is wrong
        try:
            if kind == "Arr":
                if not isinstance(v, list):
                    raise DecodeError(f"{name}.{k}: expected {_spec_words(s)}, got {json.dumps(v)}")
                try:
                    v = np.asarray(v, dtype=s.dtype)
                except (ValueError, TypeError):
                    raise DecodeError(f"{name}.{k}: expected {_spec_words(s)}, got {json.dumps(v)}") from None
            elif kind == "Strs" and isinstance(v, list):
                v = tuple(v)
            out[k] = s.check(v, f"{name}.{k}")
        except DecodeError as exc:
            raise UserError(str(exc)) from None
    return out
