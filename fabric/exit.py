"""Close what a script left open, before Python waits for its threads.

zenoh-python runs each Python callback (subscribers, queryables, liveliness
watchers) on a non-daemon Python thread of its own, which ends only when the
callback is undeclared. A script that opens a session and never closes it
therefore never exits: the interpreter joins those threads forever.
``atexit`` is too late, its functions run after the threads are joined.

:func:`at_exit` registers a closer that runs first, in the order a stack
unwinds (newest first, so a user's world releases its robots before its
session closes). It uses ``threading._register_atexit``, the hook
``concurrent.futures`` relies on for the same reason (CPython 3.9+); where it
is missing, plain ``atexit`` is the fallback.
"""

from __future__ import annotations

import atexit
import inspect
import itertools
import logging
import threading
import weakref
from typing import Callable

log = logging.getLogger("robofabric")

__all__ = ["at_exit"]

_closers: dict[int, Callable[[], None]] = {}
_ids = itertools.count()
_lock = threading.Lock()
_installed = False


def _run_closers() -> None:
    while True:
        with _lock:
            if not _closers:
                return
            key = max(_closers)
            fn = _closers.pop(key)
        try:
            fn()
        except Exception:  # one closer failing must not keep the others (or the interpreter) waiting
            log.debug("closing at exit failed", exc_info=True)


def _install() -> None:
    global _installed
    if _installed:
        return
    register = getattr(threading, "_register_atexit", None)
    try:
        if register is None:
            raise RuntimeError("no threading._register_atexit")
        register(_run_closers)
    except RuntimeError:  # missing, or the interpreter is already shutting down
        atexit.register(_run_closers)
    _installed = True


def at_exit(fn: Callable[[], None]) -> Callable[[], None]:
    """Call ``fn`` when the interpreter exits, before non-daemon threads are joined; returns a
    function that cancels it (call it from an explicit ``close()``, so nothing is closed twice).

    A bound method is held weakly: registering ``obj.close`` does not keep ``obj`` alive, so an object
    nobody refers to any more is collected as it was before (and is simply not closed again at exit)."""
    if inspect.ismethod(fn):
        ref = weakref.WeakMethod(fn)

        def call() -> None:
            method = ref()
            if method is not None:
                method()
    else:
        call = fn
    with _lock:
        _install()
        key = next(_ids)
        _closers[key] = call

    def cancel() -> None:
        with _lock:
            _closers.pop(key, None)

    return cancel
