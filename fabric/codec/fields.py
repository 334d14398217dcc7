"""Field specs: what each field of a message may hold, checked on the way in and dumped on the way out.

A message class's ``SPEC`` maps each of its fields to one of these (``F`` a finite float, ``I`` an integer,
``S`` a string, ``Strs`` names, ``User`` a user name, ``Arr`` a numpy array, ``Msg``/``Msgs`` nested messages,
``Opt`` an optional value, ``Map`` a small free-form map). ``check(value, where)`` returns the value to keep
or raises :class:`~fabric.codec.wire.DecodeError` naming the field (``where``) and what was wrong;
``dump(value)`` gives what msgpack writes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from fabric.codec.wire import DecodeError, from_list, to_list
from fabric.limits import quote, validate_user

__all__ = ["Field", "Spec", "F", "I", "S", "Strs", "User", "Arr", "Msg", "Msgs", "Opt", "Map", "MAX_ITEMS"]

MAX_ITEMS = 256
"""Default cap on a list of strings (joint names, a queue) and on a free-form map's entries."""


class Field(Protocol):
    """What every field spec offers: the codec calls nothing else, so a new spec is any class with these two."""

    def check(self, v: Any, where: str) -> Any:
        """The value to keep for wire value ``v``, or :class:`DecodeError` naming ``where`` and what was wrong."""

    def dump(self, v: Any) -> Any:
        """What msgpack writes for field value ``v``."""


Spec = dict[str, Field]
"""A message class's ``SPEC``: each field's name to its spec, in wire order."""


@dataclass(frozen=True, slots=True)
class F:
    """A finite float, optionally bounded."""

    lo: float | None = None
    hi: float | None = None

    def check(self, v: Any, where: str) -> float:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise DecodeError(f"{where}: expected a number, got {type(v).__name__}")
        x = float(v)
        if not math.isfinite(x):
            raise DecodeError(f"{where}: must be finite, got {x}")
        if self.lo is not None and x < self.lo or self.hi is not None and x > self.hi:
            raise DecodeError(f"{where}: {x} is outside [{self.lo}, {self.hi}]")
        return x

    def dump(self, v: Any) -> Any:
        return float(v)


@dataclass(frozen=True, slots=True)
class I:  # noqa: E742 (the codec's one-letter spec names: F, I, S)
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
    at :data:`fabric.codec.wire.MAX_ARRAY_BYTES` when it is unpacked, before any spec is consulted.
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
        obj = from_list(v, where)
        if not isinstance(obj, self.classes):
            names = ", ".join(c.__name__ for c in self.classes)
            raise DecodeError(f"{where}: expected {names}, got {type(obj).__name__}")
        return obj

    def dump(self, v: Any) -> Any:
        if not isinstance(v, self.classes):
            names = ", ".join(c.__name__ for c in self.classes)
            raise TypeError(f"expected {names}, got {type(v).__name__}")
        return to_list(v)


class Msgs:
    """A list of nested messages of the given classes (``Msg`` for a single one)."""

    def __init__(self, *classes: type, max_items: int = 10_000) -> None:
        self.one = Msg(*classes)
        self.max_items = max_items

    def check(self, v: Any, where: str) -> tuple[Any, ...]:
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

    inner: Field

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

    def check(self, v: Any, where: str) -> dict[str, Any]:
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
