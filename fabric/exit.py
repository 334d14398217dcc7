"""Close what a script left open, before Python waits for its threads.

zenoh-python runs each Python callback (subscribers, queryables, liveliness
watchers) on a non-daemon Python thread of its own, which ends only when the
callback is undeclared. A script that opens a session and never closes it
therefore never exits: the interpreter joins those threads forever.
``atexit`` is too late, its functions run after the threads are joined.

:func:`at_exit` registers a closer that runs first, in the order a stack
unwinds (newest first, so a user's world releases its robots before its
session closes). The first registration starts one idle non-daemon thread that
waits for the main thread to finish (``threading.main_thread().join()``):
Python marks the main thread finished before it joins the other non-daemon
threads, so the waiter wakes then and closes what is open, after which those
threads end and the interpreter can join them. Only public ``threading`` calls;
when the main thread has already finished (a registration during shutdown),
plain ``atexit`` is the fallback.
"""

from __future__ import annotations

import atexit
import inspect
import itertools
import logging
import os
import threading
import weakref
from typing import Callable

log = logging.getLogger("robofabric")

__all__ = ["at_exit"]

_closers: dict[int, Callable[[], object]] = {}
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
    try:
        if not threading.main_thread().is_alive():
            raise RuntimeError("the main thread has finished")
        threading.Thread(target=_after_main, name="robofabric-at-exit", daemon=False).start()
    except RuntimeError:  # the interpreter is already shutting down: no new thread, nothing left to wait for
        atexit.register(_run_closers)
    _installed = True


def _after_main() -> None:
    """Wait for the main thread to finish, then close: it runs before Python joins the other threads."""
    threading.main_thread().join()
    _run_closers()


def _forked() -> None:
    """A forked child has none of its parent's threads: its next registration starts its own waiter."""
    global _installed
    _installed = False


os.register_at_fork(after_in_child=_forked)


def at_exit(fn: Callable[[], object]) -> Callable[[], None]:
    """Call ``fn`` when the interpreter exits, before non-daemon threads are joined; returns a
    function that cancels it (call it from an explicit ``close()``, so nothing is closed twice).

    A bound method is held weakly: registering ``obj.close`` does not keep ``obj`` alive, so an object
    nobody refers to any more is collected as it was before (and is simply not closed again at exit)."""
    call: Callable[[], object] = fn
    if inspect.ismethod(fn):
        ref = weakref.WeakMethod(fn)

        def weak_call() -> None:
            method = ref()
            if method is not None:
                method()

        call = weak_call
    with _lock:
        _install()
        key = next(_ids)
        _closers[key] = call

    def cancel() -> None:
        with _lock:
            _closers.pop(key, None)

    return cancel
