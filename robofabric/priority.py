"""A test's CPU priority, for it and every process it starts: the suite's pages before the rest of the box.

`make test` runs four pytest-xdist workers on two cores, at load 15-25. A student's page and its console server
then wait behind three other workers' sims, routers and solvers, which a classroom never puts on her machine: the
browser tests' sockets dropped for tens of seconds, their pages were reloaded, and half of the failures of whole
runs were theirs (docs/testing.md). Their worker runs them at a higher priority (a lower nice value), its threads
and every process under it alike; the other tests keep the default. Linux's nice value is per thread, so each
thread of the worker and of its children is set, not the process alone.

A lower nice value needs the privilege to raise priority (root, or ``RLIMIT_NICE``): without it nothing changes,
and the suite runs as before.
"""

from __future__ import annotations

import os
from pathlib import Path

from robofabric.hang_watch import children_of, descendants

__all__ = ["set_tree_nice", "threads_of"]


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
