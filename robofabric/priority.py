"""A test's CPU priority, for it and every process it starts: the suite's pages before the rest of the box.

`make test` runs four pytest-xdist workers on two cores, at load 15-25. A student's page and its console server
then wait behind three other workers' sims, routers and solvers, which a classroom never puts on her machine: the
browser tests' sockets dropped for tens of seconds, their pages were reloaded, and half of the failures of whole
runs were theirs (docs/testing.md). Their worker runs them at a higher priority (a lower nice value), its threads
and every process under it alike; the other tests keep the default. Linux's nice value is per thread, so each
thread of the worker and of its children is set, not the process alone.

A lower nice value needs the privilege to raise priority (root, or ``RLIMIT_NICE``): without it nothing changes,
and the suite runs as before.

Set once, it did not reach the pages themselves: Chromium sets its own processes' values (a page's renderer 0, a
spare renderer 5). :class:`NiceKeeper` sets the tree again every few seconds while the pages' tests run. Held, it
did not end the pages' dropped sockets at load (beside whole runs, 2026-12-02, pages still reloaded with "implicit
handshake failed"): Chromium's GPU process, drawing the console's 3D view in software, used 0.85 of a core for one
page on a quiet box.
"""

from __future__ import annotations

import os
import threading
from pathlib import Path

from robofabric.hang_watch import children_of, descendants

__all__ = ["NiceKeeper", "set_tree_nice", "threads_of"]


def threads_of(pid: int, proc_root: Path = Path("/proc")) -> list[int]:
    """The thread ids of ``pid`` ([] when it is gone)."""
    try:
        return [int(t.name) for t in (proc_root / str(pid) / "task").iterdir() if t.name.isdigit()]
    except OSError:
        return []


def set_tree_nice(nice: int, pid: int | None = None) -> bool:
    """Set the nice value of every thread of ``pid`` (this process by default) and of every process under it.
    False where it was not allowed (no privilege to lower it); a thread or process gone meanwhile is passed over."""
    root = os.getpid() if pid is None else pid
    allowed = True
    for p in [root, *descendants(root, children_of())]:
        for tid in threads_of(p):
            try:
                os.setpriority(os.PRIO_PROCESS, tid, nice)
            except PermissionError:
                allowed = False
            except OSError:  # gone
                pass
    return allowed


class NiceKeeper:
    """Holds the tree under ``pid`` (this process by default) at ``nice`` from :meth:`start` to :meth:`stop`: set
    again every ``every`` seconds, for the processes started since and those that set their own."""

    def __init__(self, nice: int, pid: int | None = None, every: float = 2.0) -> None:
        self.nice, self.pid, self.every = nice, pid, every
        self.allowed = True
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> "NiceKeeper":
        self.allowed = set_tree_nice(self.nice, self.pid)
        if self.allowed:  # without the privilege, nothing to hold
            self._thread = threading.Thread(target=self._hold, name="nice-keeper", daemon=True)
            self._thread.start()
        return self

    def _hold(self) -> None:
        while not self._stop.wait(self.every):
            set_tree_nice(self.nice, self.pid)

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=10)
