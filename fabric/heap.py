"""A long-lived peer's native heap: give back to the system what zenoh's threads freed.

The 60-minute soak saw a sim's resident memory grow 43-90 MB/h while its Python objects stayed flat
(tracemalloc and ``gc`` counted nothing new). The growth came in steps of 1-7 MB, each at a router restart,
mostly while the sim was a standby (its 20 state queries a second and the streams it hears, in flight when the
link drops): zenoh's native threads allocate and free their buffers through glibc's malloc, and glibc keeps
freed chunks in the arena of the thread that freed them instead of returning the pages. Nothing leaked
(``malloc_trim`` gives the memory back), but a process that lives through a class's hours of faults must
not look like it leaks, nor take more of a student's laptop by the hour. Every peer's session has those
threads; the sims showed it most, and the compute peer and the recorder grew too (12-36 MB/h in the soaks).

So a long-lived peer (``robofabric sim``, ``compute``, ``record``) caps glibc's arenas (:func:`limit_arenas`:
freed memory is reused by the next thread that allocates rather than kept per thread) and trims its heap now
and then (:class:`HeapTrimmer`). Both are no-ops where the C library is not glibc (musl, macOS): they report
that they did nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging
import threading
from typing import Callable

log = logging.getLogger("robofabric")

__all__ = ["ARENAS", "TRIM_EVERY_S", "HeapTrimmer", "limit_arenas", "trim"]

ARENAS = 2
"""glibc's arenas a peer may have (its default: 8 per core). Two: the main thread's and one the others share."""

TRIM_EVERY_S = 30.0
"""How often a peer trims its heap: a trim of a ~100 MB heap takes a millisecond or two."""

_M_ARENA_MAX = -8  # glibc's malloc.h


def _glibc() -> ctypes.CDLL | None:
    """The C library if it is glibc (it has ``malloc_trim`` and ``mallopt``), else None."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        libc.malloc_trim, libc.mallopt  # noqa: B018 - absent outside glibc
    except (OSError, AttributeError):
        return None
    return libc


def limit_arenas(arenas: int = ARENAS) -> bool:
    """Cap glibc's malloc arenas for the threads started from now on; True if the cap was set."""
    libc = _glibc()
    return bool(libc is not None and libc.mallopt(_M_ARENA_MAX, int(arenas)) == 1)


def trim() -> bool:
    """Return the free pages of every arena to the system; True if glibc released any."""
    libc = _glibc()
    return bool(libc is not None and libc.malloc_trim(0))


class HeapTrimmer:
    """Trims the heap every ``every_s`` on a daemon thread until closed (a context manager).

    ``trimmer`` is what trims (:func:`trim`; tests pass a counter)."""

    def __init__(self, every_s: float = TRIM_EVERY_S, *, trimmer: Callable[[], bool] = trim) -> None:
        self.every_s = every_s
        self.trimmer = trimmer
        self.trims = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> "HeapTrimmer":
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="heap-trim", daemon=True)
            self._thread.start()
        return self

    def _run(self) -> None:
        while not self._stop.wait(self.every_s):
            try:
                self.trimmer()
                self.trims += 1
            except Exception:  # a trim that fails must never take the peer down
                log.debug("heap trim failed", exc_info=True)

    def close(self) -> None:
        """Stop trimming; idempotent. Waits for a trim under way."""
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(5.0)

    def __enter__(self) -> "HeapTrimmer":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()
