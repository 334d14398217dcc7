"""msgpack codec for fabric messages, with validation on the way in.

Wire form: a msgpack array ``[TYPE, field1, field2, ...]`` in the order of the
class's ``SPEC`` (positional, so field names cost no bytes). numpy arrays
travel as one msgpack ext (code 1) holding a dtype code, the shape and the raw
little-endian bytes, never element by element: a 240-ray scan is ~560 bytes.

Decoding trusts nothing. Every failure, from random bytes to a NaN hidden in a
nested command, raises :class:`DecodeError` with a message saying which field
was wrong and how, so a peer can count it, publish an event and go on.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import struct
from dataclasses import dataclass
from typing import Any

import msgpack
import numpy as np

from fabric.limits import quote, validate_user

__all__ = [
    "DecodeError",
    "encode",
    "decode",
    "register",
    "registered",
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
]

EXT_NDARRAY = 1
MAX_ARRAY_BYTES = 16 * 1024 * 1024
"""No array field may be larger, whatever its spec says (routers cap messages at a few MB anyway)."""
MAX_ITEMS = 256
"""Default cap on a list of strings (joint names, a queue) and on a free-form map's entries."""
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


# --------------------------------------------------------------------------- field specs


@dataclass(frozen=True, slots=True)
class F:
    """A finite float, optionally bounded."""

    lo: float | None = None
    hi: float | None = None

    def check(self, v: Any, where: str) -> float:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise DecodeError(f"{where}: expected a number, got {type(v).__name__}")
        v = float(v)
        if not math.isfinite(v):
            raise DecodeError(f"{where}: must be finite, got {v}")
        if self.lo is not None and v < self.lo or self.hi is not None and v > self.hi:
            raise DecodeError(f"{where}: {v} is outside [{self.lo}, {self.hi}]")
        return v

    def dump(self, v: Any) -> Any:
        return float(v)


@dataclass(frozen=True, slots=True)
class I:
    """An integer, optionally bounded."""

    lo: int | None = None
    hi: int | None = None

    def check(self, v: Any, where: str) -> int:
        if isinstance(v, bool) or not isinstance(v, int):
            raise DecodeError(f"{where}: expected an integer, got {type(v).__name__}")
        if self.lo is not None and v < self.lo or self.hi is not None and v > self.hi:
            raise DecodeError(f"{where}: {v} is outside [{self.lo}, {self.hi}]")
        return v

    def dump(self, v: Any) -> Any:
        return int(v)


@dataclass(frozen=True, slots=True)
class S:
    """A string, optionally non-empty or one of ``choices``."""

    nonempty: bool = False
    choices: tuple[str, ...] | None = None
    max_len: int = 4096

    def check(self, v: Any, where: str) -> str:
        if not isinstance(v, str):
            raise DecodeError(f"{where}: expected a string, got {type(v).__name__}")
        if self.nonempty and not v:
            raise DecodeError(f"{where}: must not be empty")
        if len(v) > self.max_len:
            raise DecodeError(f"{where}: string of {len(v)} characters is too long")
        if self.choices is not None and v not in self.choices:
            raise DecodeError(f"{where}: {quote(v)} is not one of {', '.join(self.choices)}")
        return v

    def dump(self, v: Any) -> Any:
        return v


@dataclass(frozen=True, slots=True)
class Strs:
    """A list of at most ``max_items`` strings of at most ``max_len`` characters (names, queues)."""

    max_items: int = MAX_ITEMS
    max_len: int = 256

    def check(self, v: Any, where: str) -> tuple[str, ...]:
        if not isinstance(v, (list, tuple)):
            raise DecodeError(f"{where}: expected a list of strings, got {type(v).__name__}")
        if len(v) > self.max_items:
            raise DecodeError(f"{where}: {len(v)} strings is too many (at most {self.max_items})")
        for i, s in enumerate(v):
            if not isinstance(s, str):
                raise DecodeError(f"{where}[{i}]: expected a string, got {type(s).__name__}")
            if len(s) > self.max_len:
                raise DecodeError(f"{where}[{i}]: string of {len(s)} characters is too long (at most {self.max_len})")
        return tuple(v)

    def dump(self, v: Any) -> Any:
        return list(v)


@dataclass(frozen=True, slots=True)
class User:
    """A user name (:func:`fabric.limits.validate_user`: at most 64 characters of a safe alphabet)."""

    def check(self, v: Any, where: str) -> str:
        try:
            return validate_user(v, what=where)
        except ValueError as exc:
            raise DecodeError(str(exc)) from None

    def dump(self, v: Any) -> Any:
        return v


@dataclass(frozen=True, slots=True)
class Arr:
    """A numpy array of one dtype, with a fixed shape or a fixed number of dims; finite if float.

    ``max_elems`` caps its size (a scan cannot hold a million rays); every array is also capped
    at :data:`MAX_ARRAY_BYTES` when it is unpacked, before any spec is consulted.
    """

    dtype: Any
    ndim: int | None = None
    shape: tuple[int, ...] | None = None
    max_elems: int = 1 << 16

    def check(self, v: Any, where: str) -> np.ndarray:
        if not isinstance(v, np.ndarray):
            raise DecodeError(f"{where}: expected an array, got {type(v).__name__}")
        want = np.dtype(self.dtype)
        if v.dtype != want:
            raise DecodeError(f"{where}: expected dtype {want.name}, got {v.dtype.name}")
        if self.shape is not None and tuple(v.shape) != tuple(self.shape):
            raise DecodeError(f"{where}: expected shape {tuple(self.shape)}, got {tuple(v.shape)}")
        if self.ndim is not None and v.ndim != self.ndim:
            raise DecodeError(f"{where}: expected {self.ndim}-D array, got shape {tuple(v.shape)}")
        if v.size > self.max_elems:
            raise DecodeError(f"{where}: {v.size} elements is too many (at most {self.max_elems})")
        if v.dtype.kind == "f" and not np.isfinite(v).all():
            bad = int(np.flatnonzero(~np.isfinite(v.ravel()))[0])
            raise DecodeError(f"{where}: element {bad} is not finite ({v.ravel()[bad]})")
        return v

    def dump(self, v: Any) -> Any:
        return np.asarray(v, dtype=self.dtype)


@dataclass(frozen=True, slots=True)
class Msg:
    """A nested message of one of the given classes."""

    classes: tuple[type, ...]

    def __init__(self, *classes: type) -> None:
        object.__setattr__(self, "classes", classes)

    def check(self, v: Any, where: str) -> Any:
        if not isinstance(v, list):
            raise DecodeError(f"{where}: expected a nested message, got {type(v).__name__}")
        obj = _from_list(v, where)
        if not isinstance(obj, self.classes):
            names = ", ".join(c.__name__ for c in self.classes)
            raise DecodeError(f"{where}: expected {names}, got {type(obj).__name__}")
        return obj

    def dump(self, v: Any) -> Any:
        if not isinstance(v, self.classes):
            names = ", ".join(c.__name__ for c in self.classes)
            raise TypeError(f"expected {names}, got {type(v).__name__}")
        return _to_list(v)


class Msgs:
    """A list of nested messages of the given classes (``Msg`` for a single one)."""

    def __init__(self, *classes: type, max_items: int = 10_000) -> None:
        self.one = Msg(*classes)
        self.max_items = max_items

    def check(self, v: Any, where: str) -> tuple:
        if not isinstance(v, list):
            raise DecodeError(f"{where}: expected a list of messages, got {type(v).__name__}")
        if len(v) > self.max_items:
            raise DecodeError(f"{where}: {len(v)} entries is too many (at most {self.max_items})")
        return tuple(self.one.check(x, f"{where}[{i}]") for i, x in enumerate(v))

    def dump(self, v: Any) -> Any:
        return [self.one.dump(x) for x in v]


@dataclass(frozen=True, slots=True)
class Opt:
    """``inner`` or nothing: None travels as msgpack nil (a robot without a LIDAR has no ``lidar``)."""

    inner: Any

    def check(self, v: Any, where: str) -> Any:
        return None if v is None else self.inner.check(v, where)

    def dump(self, v: Any) -> Any:
        return None if v is None else self.inner.dump(v)


_SCALARS = (str, int, float, bool, type(None))


@dataclass(frozen=True, slots=True)
class Map:
    """A small free-form map of string keys to scalars or lists of scalars (event details)."""

    max_items: int = MAX_ITEMS
    max_list: int = 4096

    def check(self, v: Any, where: str) -> dict:
        if not isinstance(v, dict):
            raise DecodeError(f"{where}: expected a map, got {type(v).__name__}")
        if len(v) > self.max_items:
            raise DecodeError(f"{where}: {len(v)} entries is too many (at most {self.max_items})")
        for k, x in v.items():
            if not isinstance(k, str):
                raise DecodeError(f"{where}: keys must be strings, got {type(k).__name__}")
            if len(k) > 256:
                raise DecodeError(f"{where}: a key of {len(k)} characters is too long (at most 256)")
            items = x if isinstance(x, list) else [x]
            if len(items) > self.max_list:
                raise DecodeError(f"{where}.{k}: {len(items)} values is too many (at most {self.max_list})")
            for item in items:
                if not isinstance(item, _SCALARS):
                    raise DecodeError(f"{where}.{k}: unsupported value of type {type(item).__name__}")
                if isinstance(item, float) and not math.isfinite(item):
                    raise DecodeError(f"{where}.{k}: must be finite, got {item}")
        return dict(v)

    def dump(self, v: Any) -> Any:
        out = {}
        for k, x in dict(v).items():
            if isinstance(x, (list, tuple, np.ndarray)):
                out[str(k)] = [_plain_scalar(i) for i in x]
            else:
                out[str(k)] = _plain_scalar(x)
        return out


def _plain_scalar(x: Any) -> Any:
    if isinstance(x, np.generic):
        return x.item()
    return x


# --------------------------------------------------------------------------- registry

_BY_NAME: dict[str, type] = {}
_NAME_OF: dict[type, str] = {}


def register(cls: type, name: str | None = None) -> type:
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


def registered() -> dict[str, type]:
    _ensure_core()
    return dict(_BY_NAME)


def _ensure_core() -> None:
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


# --------------------------------------------------------------------------- encode


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


def _ext_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        head, dtype = _array_head(obj)
        return msgpack.ExtType(EXT_NDARRAY, head + np.ascontiguousarray(obj, dtype=dtype).tobytes())
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"cannot encode {type(obj).__name__}")


@functools.lru_cache(maxsize=None)
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


def _to_list(msg: Any) -> list:
    cls = type(msg)
    name = _NAME_OF.get(cls)
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
    _ensure_core()
    check = getattr(msg, "check", None)
    if check is not None:
        check()
    return msgpack.packb(_to_list(msg), default=_ext_default, use_bin_type=True)


# --------------------------------------------------------------------------- decode


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


def _from_list(m: list, where: str) -> Any:
    if not m or not isinstance(m[0], str):
        raise DecodeError(f"{where}: missing message type tag")
    name = m[0]
    cls = _BY_NAME.get(name)
    if cls is None:
        raise DecodeError(f"{where}: unknown message type {quote(name, 64)}")
    spec: dict = cls.SPEC
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


def decode(payload: bytes | bytearray | memoryview, expected: type | tuple[type, ...] | None = None) -> Any:
    """Decode and validate bytes into a message; raise :class:`DecodeError` on anything wrong."""
    _ensure_core()
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
        obj = _from_list(raw, "message")
    except DecodeError:
        raise
    except RecursionError:
        raise DecodeError("message nested too deeply") from None
    if expected is not None and not isinstance(obj, expected):
        names = ", ".join(c.__name__ for c in (expected if isinstance(expected, tuple) else (expected,)))
        raise DecodeError(f"expected {names}, got {type(obj).__name__}")
    return obj


# --------------------------------------------------------------------------- helpers


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
    return a == b
