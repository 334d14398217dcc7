"""The fields of each message type, as ``robofabric interfaces`` and ``info KEY`` list them.

Read off the classes' ``SPEC`` (the table the decoder checks), as the JSON Schema in
:mod:`user_peer.message_schema` is, so the listing cannot drift from the wire. Listing types for a
person is introspection, a tool's need: it sits on the top floor, while the JSON Schema and the plain
view that the user peer's exports write sit with them, in :mod:`user_peer`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from fabric.codec import Arr, F, I, Map, Msg, Opt, S, Strs, load_plugins, registered
from user_peer.message_schema import type_name

__all__ = ["FieldInfo", "fields_of", "describe_spec", "message_types"]


@dataclass(frozen=True, slots=True)
class FieldInfo:
    """One field of a message type: name, a short type text (``float64[3]``, ``Header``) and its constraints."""

    name: str
    type: str
    constraints: str = ""
    default: str = ""


def message_types() -> dict[str, type]:
    """Every message type the codec knows, installed plugins' included, by name."""
    load_plugins()
    return dict(sorted(registered().items()))


def _range(lo: Any, hi: Any) -> str:
    if lo is None and hi is None:
        return ""
    return f"[{'-inf' if lo is None else f'{lo:g}'}, {'inf' if hi is None else f'{hi:g}'}]"


def describe_spec(spec: Any) -> tuple[str, str]:
    """(type text, constraints text) of one field spec."""
    if isinstance(spec, Opt):
        t, c = describe_spec(spec.inner)
        return f"{t} | None", c
    if isinstance(spec, F):
        return "float", _range(spec.lo, spec.hi)
    if isinstance(spec, I):
        return "int", _range(spec.lo, spec.hi)
    if isinstance(spec, S):
        parts = []
        if spec.choices:
            parts.append("one of " + ", ".join(spec.choices))
        if spec.nonempty:
            parts.append("non-empty")
        return "string", "; ".join(parts)
    if isinstance(spec, Strs):
        return "string[]", ""
    if isinstance(spec, Arr):
        dt = np.dtype(spec.dtype).name
        if spec.shape is not None:
            return dt + "".join(f"[{n}]" for n in spec.shape), ""
        return dt + "[]" * (spec.ndim or 1), ""
    if isinstance(spec, Msg):
        return " | ".join(type_name(c) for c in spec.classes), ""
    if isinstance(spec, Map):
        return "map", "string keys; scalars or lists of scalars"
    one = getattr(spec, "one", None)
    if isinstance(one, Msg):
        return f"{' | '.join(type_name(c) for c in one.classes)}[]", ""
    return type(spec).__name__, ""


def _default_text(f: dataclasses.Field) -> str:
    if f.default is not dataclasses.MISSING:
        return repr(f.default)
    if f.default_factory is not dataclasses.MISSING:  # type: ignore[misc]
        try:
            v = f.default_factory()  # type: ignore[misc]
        except Exception:
            return ""
        if isinstance(v, np.ndarray):
            return repr(v.tolist())
        if dataclasses.is_dataclass(v):
            return f"{type(v).__name__}()"
        return repr(v)
    return ""


def fields_of(cls: type) -> list[FieldInfo]:
    """The fields of a message class in wire order, with types, constraints and defaults."""
    by_name = {f.name: f for f in dataclasses.fields(cls)} if dataclasses.is_dataclass(cls) else {}
    out = []
    for name, spec in cls.SPEC.items():
        t, c = describe_spec(spec)
        f = by_name.get(name)
        out.append(FieldInfo(name, t, c, _default_text(f) if f is not None else ""))
    return out
