"""The suite's last resort against a test that hangs where pytest-timeout cannot reach it.

pytest-timeout's signal method raises in the main thread, which Python can only do between two bytecodes: a main
thread parked inside a native call (a zenoh session's close or a reply's wait, parked in Rust with the GIL given
up) never sees it, and its pytest-xdist worker waits for ever. CI saw it once: `make test` stopped 2 tests short
of 1,705 and sat idle until CI's 90 minutes ended it, with nothing said of which test or where.

A test still running past its own timeout and a grace (its teardown's) is ended from outside its main thread:
every thread's stack is written to stderr (pytest-xdist passes a worker's stderr to the run's output), the
processes it started are killed by pid (they run in sessions of their own, so no signal of the worker's would
reach them), and the worker exits; pytest-xdist then reports the test as crashed, starts a new worker and runs
on. Where even that thread cannot run (a native call that holds the GIL), faulthandler's own C thread writes
the stacks a minute later and exits the worker, leaving the processes.
"""

from __future__ import annotations

import faulthandler
import os
import signal
import threading
from pathlib import Path
from typing import TextIO

HUNG_EXIT = 86  # the worker's exit status when this ended it (pytest-xdist says "crashed")
GRACE_S = 120.0  # after the test's timeout: its teardown's, which pytest-timeout lets run untimed
BACKSTOP_S = 60.0  # after the watch's own limit: faulthandler's C thread, for a watch thread that cannot run


def children_of(proc_root: Path = Path("/proc")) -> dict[int, list[int]]:
    """Each process's children, from ``/proc/*/stat`` (a process gone while it is read is left out)."""
    children: dict[int, list[int]] = {}
    for entry in proc_root.iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        # the command's name is in parentheses and may hold spaces or parentheses: the fields follow the last ")"
        fields = stat[stat.rfind(")") + 2 :].split()
        if len(fields) >= 2 and fields[1].isdigit():
            children.setdefault(int(fields[1]), []).append(int(entry.name))
    return children


def descendants(pid: int, children: dict[int, list[int]]) -> list[int]:
    """Every process under ``pid`` (children before their children), however many sessions deep."""
    found: list[int] = []
    todo = list(children.get(pid, ()))
    while todo:
        child = todo.pop(0)
        if child in found or child == pid:
            continue
        found.append(child)
        todo.extend(children.get(child, ()))
    return found


def run_stderr() -> TextIO:
    """The process's stderr as it is now, kept open: taken at pytest's configure, before a test's output is
    captured (pytest points descriptor 2 at a file of its own during a test, lost if the worker exits)."""
    return os.fdopen(os.dup(2), "w", buffering=1)


class HangWatch:
    """One test at a time: :meth:`arm` when it starts, :meth:`disarm` when its teardown is done."""

    def __init__(self, out: TextIO, grace_s: float = GRACE_S, backstop_s: float = BACKSTOP_S) -> None:
        """``out``: the run's own stderr, taken before pytest's capture of a test's (see :func:`run_stderr`)."""
        self.out = out
        self.grace_s = grace_s
        self.backstop_s = backstop_s
        self._timer: threading.Timer | None = None

    def arm(self, nodeid: str, timeout_s: float) -> None:
        """Watch a test whose own timeout is ``timeout_s`` (0: none, and no watch either, as pytest-timeout)."""
        self.disarm()
        if timeout_s <= 0:
            return
        limit = timeout_s + self.grace_s
        self._timer = threading.Timer(limit, self._hung, args=(nodeid, limit))
        self._timer.daemon = True
        self._timer.name = "hang-watch"
        self._timer.start()
        faulthandler.dump_traceback_later(limit + self.backstop_s, exit=True, file=self.out)

    def disarm(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
            faulthandler.cancel_dump_traceback_later()

    def _hung(self, nodeid: str, limit: float) -> None:
        out = self.out
        pids = descendants(os.getpid(), children_of())
        out.write(
            f"\n+++ hang watch: {nodeid} still running {limit:.0f} s after it started (its timeout and "
            f"{self.grace_s:.0f} s of teardown; pytest-timeout could not end it). Every thread's stack, then "
            f"its {len(pids)} process(es) {pids} are killed and this worker (pid {os.getpid()}) exits "
            f"{HUNG_EXIT}:\n"
        )
        out.flush()
        faulthandler.dump_traceback(file=out, all_threads=True)
        out.flush()
        for pid in pids:
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass
        os._exit(HUNG_EXIT)
