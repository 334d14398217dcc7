"""The wire format: a msgpack array ``[TYPE, field1, field2, ...]``, and encoding and decoding it with validation.

Fields travel in the order of the class's ``SPEC`` (positional, so field names cost no bytes). numpy arrays
travel as one msgpack ext (code 1) holding a dtype code, the shape and the raw little-endian bytes, never
element by element: a 240-ray scan is ~560 bytes.

Decoding trusts nothing. Every failure, from random bytes to a NaN hidden in a nested command, raises
:class:`DecodeError` with a message saying which field was wrong and how, so a peer can count it, publish an
event and go on.
"""

from __future__ import annotations

import dataclasses
import functools
import struct
from typing import Any, TypeVar, overload

import msgpack
import numpy as np

from fabric.codec.registry import Message, class_named, ensure_core, name_of
from fabric.limits import quote

__all__ = [
    "DecodeError",
    "encode",
    "decode",
    "to_list",
    "from_list",
    "array_ext",
    "EXT_NDARRAY",
    "MAX_ARRAY_BYTES",
    "MAX_DIMS",
]

EXT_NDARRAY = 1
MAX_ARRAY_BYTES = 16 * 1024 * 1024
"""No array field may be larger, whatever its spec says (routers cap messages at a few MB anyway)."""
MAX_DIMS = 4

_DTYPES: dict[int, np.dtype] = {
    1: np.dtype("<f8"),
    2: np.dtype("<f4"),
    3: np.dtype("<i8"),
    4: np.dtype("<i4"),
    5: np.dtype("<u2"),
    6: np.dtype("u1"),
    7: np.dtype("<i2"),
    8: np.dtype("<u4"),
}
_DTYPE_CODES = {dt: code for code, dt in _DTYPES.items()}


class DecodeError(ValueError):
    """A payload is not a valid fabric message; the text says what was wrong."""


_ARRAY_HEADS: dict[tuple[np.dtype, tuple[int, ...]], tuple[bytes, np.dtype]] = {}
"""(dtype, shape) -> (the extension's head bytes, the little-endian dtype written): a sim sends the same few
shapes thousands of times a second, and building the head each time was a third of an array's cost."""


def _array_head(obj: np.ndarray) -> tuple[bytes, np.dtype]:
    key = (obj.dtype, obj.shape)
    cached = _ARRAY_HEADS.get(key)
    if cached is not None:
        return cached
    dt = obj.dtype.newbyteorder("<") if obj.dtype.byteorder == ">" else obj.dtype
    code = _DTYPE_CODES.get(np.dtype(dt))
    if code is None:
        raise TypeError(f"arrays of dtype {obj.dtype} cannot be encoded")
    if obj.ndim > MAX_DIMS:
        raise TypeError(f"arrays of more than {MAX_DIMS} dims cannot be encoded")
    head = struct.pack("<BB", code, obj.ndim) + struct.pack(f"<{obj.ndim}I", *obj.shape)
    if len(_ARRAY_HEADS) < 4096:  # shapes come from our own messages and a client's; never an unbounded cache
        _ARRAY_HEADS[key] = (head, _DTYPES[code])
    return head, _DTYPES[code]


def array_ext(arr: np.ndarray) -> msgpack.ExtType:
    """An array as the wire's extension (what ``encode`` writes; tools and tests that build a payload by hand)."""
    head, dtype = _array_head(arr)
    return msgpack.ExtType(EXT_NDARRAY, head + np.ascontiguousarray(arr, dtype=dtype).tobytes())


def _ext_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return array_ext(obj)
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"cannot encode {type(obj).__name__}")


@functools.cache
def _optional_tail(cls: type) -> tuple[tuple[str, Any], ...]:
    """The trailing fields a class marks as added later (``OPTIONAL_TAIL``), with their defaults.

    Older peers and recordings lack them: they decode to the default. On the way out a trailing run
    of such fields still at their default is left off, so a message that does not use a new field
    keeps the wire form (and size) it had before the field existed."""
    n = int(getattr(cls, "OPTIONAL_TAIL", 0) or 0)
    if n <= 0:
        return ()
    fields = dataclasses.fields(cls)[-n:]
    return tuple((f.name, f.default) for f in fields)


def to_list(msg: Any) -> list[Any]:
    """A registered message as its wire array ``[TYPE, *fields]`` (nested messages as arrays, before msgpack)."""
    cls: type[Message] = type(msg)
    name = name_of(cls)
    if name is None:
        raise TypeError(f"{cls.__name__} is not a registered message type")
    out = [name, *(spec.dump(getattr(msg, key)) for key, spec in cls.SPEC.items())]
    for key, default in reversed(_optional_tail(cls)):
        if getattr(msg, key) != default:
            break
        out.pop()
    return out


def encode(msg: Any) -> bytes:
    """Encode a registered message to bytes. Raises ``TypeError`` for things that are not messages."""
    ensure_core()
    check = getattr(msg, "check", None)
    if check is not None:
        check()
    wire: bytes = msgpack.packb(to_list(msg), default=_ext_default, use_bin_type=True)
    return wire


def _ext_hook(code: int, data: bytes) -> Any:
    if code != EXT_NDARRAY:
        raise DecodeError(f"unknown msgpack extension type {code}")
    if len(data) < 2:
        raise DecodeError("truncated array header")
    dcode, ndim = data[0], data[1]
    dtype = _DTYPES.get(dcode)
    if dtype is None:
        raise DecodeError(f"unknown array dtype code {dcode}")
    if ndim > MAX_DIMS:
        raise DecodeError(f"array with {ndim} dims (at most {MAX_DIMS})")
    head = 2 + 4 * ndim
    if len(data) < head:
        raise DecodeError("truncated array shape")
    shape = struct.unpack(f"<{ndim}I", data[2:head])
    count = 1
    for s in shape:
        count *= s
    nbytes = count * dtype.itemsize
    if nbytes > MAX_ARRAY_BYTES:
        raise DecodeError(f"array of {nbytes} bytes is too large")
    if len(data) - head != nbytes:
        raise DecodeError(f"array of shape {shape} needs {nbytes} bytes, payload has {len(data) - head}")
    arr = np.frombuffer(data, dtype=dtype, offset=head, count=count).reshape(shape)
    return arr


def from_list(m: list[Any], where: str) -> Any:
    """The message a wire array stands for, every field checked by its spec; ``where`` names it in errors."""
    if not m or not isinstance(m[0], str):
        raise DecodeError(f"{where}: missing message type tag")
    name = m[0]
    cls = class_named(name)
    if cls is None:
        raise DecodeError(f"{where}: unknown message type {quote(name, 64)}")
    spec = cls.SPEC
    optional = _optional_tail(cls)
    if not len(spec) - len(optional) <= len(m) - 1 <= len(spec):
        want = f"{len(spec)}" if not optional else f"{len(spec) - len(optional)} to {len(spec)}"
        raise DecodeError(f"{name}: expected {want} fields, got {len(m) - 1}")
    kwargs = {}
    for (key, fspec), value in zip(spec.items(), m[1:]):
        kwargs[key] = fspec.check(value, f"{name}.{key}")
    try:
        obj = cls(**kwargs)
        check = getattr(obj, "check", None)
        if check is not None:
            check()
    except DecodeError:
        raise
    except (ValueError, TypeError) as exc:
        raise DecodeError(f"{name}: {exc}") from None
    return obj


_T = TypeVar("_T")


@overload
def decode(payload: bytes | bytearray | memoryview, expected: type[_T]) -> _T: ...


@overload
def decode(payload: bytes | bytearray | memoryview, expected: tuple[type, ...] | None = None) -> Any: ...


def decode(payload: bytes | bytearray | memoryview, expected: type | tuple[type, ...] | None = None) -> Any:
    """Decode and validate bytes into a message; raise :class:`DecodeError` on anything wrong."""
    ensure_core()
    if not isinstance(payload, (bytes, bytearray, memoryview)):
        raise DecodeError(f"payload must be bytes, got {type(payload).__name__}")
    if len(payload) == 0:
        raise DecodeError("empty payload")
    try:
        raw = msgpack.unpackb(bytes(payload), ext_hook=_ext_hook, raw=False, strict_map_key=False, use_list=True)
    except DecodeError:
        raise
    except Exception as exc:  # msgpack raises a zoo of types on garbage
        raise DecodeError(f"not a msgpack message ({type(exc).__name__}: {exc})") from None
    if not isinstance(raw, list):
        raise DecodeError(f"expected a message array, got {type(raw).__name__}")
    try:
        obj = from_list(raw, "message")
    except DecodeError:
        raise
    except RecursionError:
        raise DecodeError("message nested too deeply") from None
    if expected is not None and not isinstance(obj, expected):
        names = ", ".join(c.__name__ for c in (expected if isinstance(expected, tuple) else (expected,)))
        raise DecodeError(f"expected {names}, got {type(obj).__name__}")
    return obj
