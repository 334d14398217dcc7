"""Callbacks and iterators on any key of a world: the two ways a script or a notebook reads a stream."""

from __future__ import annotations

import queue
import time
from typing import Any, Callable, Iterator

from fabric.limits import put_dropping_oldest
from fabric.session import Fabric

__all__ = ["Sample", "Subscription", "StreamIterator"]


class Sample(tuple):
    """(key, message, received wall time in ns) of one message."""

    __slots__ = ()

    def __new__(cls, key: str, message: Any, received_ns: int) -> "Sample":
        return tuple.__new__(cls, (key, message, received_ns))

    @property
    def key(self) -> str:
        return self[0]

    @property
    def message(self) -> Any:
        return self[1]

    @property
    def received_ns(self) -> int:
        return self[2]


class Subscription:
    """A callback on a key expression; ``close()`` (or leaving a ``with``) stops it."""

    def __init__(self, fab: Fabric, key_expr: str, callback: Callable[[str, Any], None]) -> None:
        self.key_expr = key_expr
        self._sub = fab.subscribe(key_expr, callback)
        self._closed = False

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            try:
                self._sub.undeclare()
            except Exception:
                pass

    def __enter__(self) -> "Subscription":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class StreamIterator:
    """Iterate over messages of a key expression as they arrive; bounded, oldest dropped when full.

    ``for s in world.stream(key, timeout=5): ...`` ends after ``timeout`` seconds without a message
    (None: wait forever) or after ``limit`` messages.
    """

    def __init__(
        self, fab: Fabric, key_expr: str, *, maxsize: int = 1000, timeout: float | None = None, limit: int | None = None
    ) -> None:
        self._q: queue.Queue[Sample] = queue.Queue(maxsize=maxsize)
        self.timeout = timeout
        self.limit = limit
        self.dropped = 0
        self._n = 0
        self._sub = Subscription(fab, key_expr, self._put)

    def _put(self, key: str, msg: Any) -> None:
        self.dropped += put_dropping_oldest(self._q, Sample(key, msg, time.time_ns()))

    def __iter__(self) -> Iterator[Sample]:
        return self

    def __next__(self) -> Sample:
        if self.limit is not None and self._n >= self.limit:
            self.close()
            raise StopIteration
        try:
            s = self._q.get(timeout=self.timeout)
        except queue.Empty:
            self.close()
            raise StopIteration from None
        self._n += 1
        return s

    def close(self) -> None:
        self._sub.close()

    def __enter__(self) -> "StreamIterator":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
