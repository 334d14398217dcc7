"""What each message type looks like from outside, as JSON: a plain view of a message and its JSON Schema.

Both are read off the classes' ``SPEC`` (the same table the decoder validates
against), so they cannot drift from the wire format. The JSON Schema describes
:func:`plain_view` of a message (arrays as nested lists, a ``type`` member
naming the class); exports that write JSON channels declare it
so a reader (Foxglove, ``jsonschema``) can check every message.

Not on the ground floor: no peer sends or checks JSON at run time. The exporters here in
:mod:`user_peer.openfmt` write both, and the introspection tools a floor above
(``robofabric interfaces``) print them, so they live in the lowest package that uses them.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fabric.codec import Arr, F, I, Map, Msg, Opt, S, Strs, registered, to_plain

__all__ = ["json_schema", "plain_view", "type_doc", "type_name"]


def type_name(cls: type) -> str:
    """The name a message class is registered under (its wire type name), or its class name."""
    for name, c in registered().items():
        if c is cls:
            return name
    return cls.__name__


def plain_view(msg: Any) -> dict[str, Any]:
    """A message as JSON-ready data following its ``SPEC`` (what :func:`json_schema` describes).

    Like :func:`fabric.codec.to_plain`, with each field in its wire form: an ``I`` field is an integer
    even where the class holds a bool, an ``F`` field a float.
    """
    out: dict[str, Any] = {"type": type_name(type(msg))}
    for name, spec in type(msg).SPEC.items():
        out[name] = _plain_field(spec, getattr(msg, name))
    return out


def _plain_field(spec: Any, v: Any) -> Any:
    if isinstance(spec, Opt):
        return None if v is None else _plain_field(spec.inner, v)
    if isinstance(spec, F):
        return float(v)
    if isinstance(spec, I):
        return int(v)
    if isinstance(spec, S):
        return str(v)
    if isinstance(spec, Strs):
        return [str(x) for x in v]
    if isinstance(spec, Arr):
        return np.asarray(v).tolist()
    if isinstance(spec, Msg):
        return plain_view(v)
    if isinstance(spec, Map):
        return spec.dump(v)
    one = getattr(spec, "one", None)
    if isinstance(one, Msg):
        return [plain_view(x) for x in v]
    return to_plain(v)


_SCALAR = {"type": ["string", "number", "integer", "boolean", "null"]}


def _spec_schema(spec: Any, defs: dict[str, Any]) -> dict[str, Any]:
    if isinstance(spec, Opt):
        return {"anyOf": [_spec_schema(spec.inner, defs), {"type": "null"}]}
    if isinstance(spec, F):
        s: dict[str, Any] = {"type": "number"}
        if spec.lo is not None:
            s["minimum"] = spec.lo
        if spec.hi is not None:
            s["maximum"] = spec.hi
        return s
    if isinstance(spec, I):
        s = {"type": "integer"}
        if spec.lo is not None:
            s["minimum"] = spec.lo
        if spec.hi is not None:
            s["maximum"] = spec.hi
        return s
    if isinstance(spec, S):
        s = {"type": "string"}
        if spec.choices:
            s["enum"] = list(spec.choices)
        if spec.nonempty:
            s["minLength"] = 1
        return s
    if isinstance(spec, Strs):
        return {"type": "array", "items": {"type": "string"}}
    if isinstance(spec, Arr):
        item: dict[str, Any] = {"type": "integer" if np.dtype(spec.dtype).kind in "iu" else "number"}
        if spec.shape is not None:
            for n in reversed(spec.shape):
                item = {"type": "array", "items": item, "minItems": n, "maxItems": n}
            return item
        for _ in range(spec.ndim or 1):
            item = {"type": "array", "items": item}
        return item
    if isinstance(spec, Msg):
        refs = [_ref(c, defs) for c in spec.classes]
        return refs[0] if len(refs) == 1 else {"anyOf": refs}
    if isinstance(spec, Map):
        return {"type": "object", "additionalProperties": {"anyOf": [_SCALAR, {"type": "array", "items": _SCALAR}]}}
    one = getattr(spec, "one", None)
    if isinstance(one, Msg):
        return {"type": "array", "items": _spec_schema(one, defs)}
    return {}


def _object_schema(cls: type, defs: dict[str, Any]) -> dict[str, Any]:
    name = type_name(cls)
    props: dict[str, Any] = {"type": {"const": name}}
    for field, spec in cls.SPEC.items():
        props[field] = _spec_schema(spec, defs)
    doc = type_doc(cls)
    # a class with a field named ``type`` (RobotInfo) shadows the tag in plain_view: list it once
    required = list(dict.fromkeys(["type", *cls.SPEC]))
    out: dict[str, Any] = {"type": "object", "title": name, "properties": props, "required": required}
    if doc:
        out["description"] = " ".join(doc.split())
    return out


def type_doc(cls: type) -> str:
    """The first paragraph of a message class's docstring ("" for dataclasses' generated signature)."""
    doc = (cls.__doc__ or "").strip()
    if not doc or doc.startswith(f"{cls.__name__}("):
        return ""
    return " ".join(doc.split("\n\n")[0].split())


def _ref(cls: type, defs: dict[str, Any]) -> dict[str, Any]:
    name = type_name(cls)
    if name not in defs:
        defs[name] = {}  # placeholder first: a type may (indirectly) contain itself
        defs[name] = _object_schema(cls, defs)
    return {"$ref": f"#/$defs/{name}"}


def json_schema(cls: type, *, extra: dict[str, Any] | None = None) -> dict[str, Any]:
    """A JSON Schema (draft 2020-12) of :func:`plain_view` for messages of ``cls``.

    ``extra`` adds properties (name -> schema) that a writer puts beside the message's own fields.
    """
    defs: dict[str, Any] = {}
    top = _object_schema(cls, defs)
    if extra:
        top["properties"].update(extra)
        top["required"] = [*top["required"], *extra]
    top["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    if defs:
        top["$defs"] = defs
    return top
