"""A test's priority reaches every thread of its process and of the processes under it (robofabric/priority.py)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

import os

from robofabric.priority import NiceKeeper, set_tree_nice, threads_of
from robofabric.testing import wait_until

# a process with a second thread, and a child of its own with a thread too
TREE = """
import subprocess, sys, threading, time
threading.Thread(target=time.sleep, args=(60,), daemon=True).start()
if sys.argv[1] == "parent":
    subprocess.Popen([sys.executable, "-c", sys.argv[2], "child", ""])
time.sleep(60)
"""


def _nice(pid: int, tid: int) -> int:
    stat = (Path("/proc") / str(pid) / "task" / str(tid) / "stat").read_text()
    return int(stat[stat.rfind(")") + 2 :].split()[16])  # field 19: nice


def _tree(pid: int) -> list[int]:
    """``pid`` and its child, once both have their second thread."""
    from robofabric.hang_watch import children_of

    def tree() -> list[int] | None:
        kids = children_of().get(pid, [])
        ok = kids and len(threads_of(pid)) >= 2 and len(threads_of(kids[0])) >= 2
        return [pid, kids[0]] if ok else None

    return wait_until(tree, timeout=30, what="the process, its child and their threads")


@pytest.mark.slow  # it starts processes
def test_every_thread_of_a_process_and_of_its_children_gets_the_nice_value() -> None:
    parent = subprocess.Popen([sys.executable, "-c", TREE, "parent", TREE], start_new_session=True)
    try:
        pids = _tree(parent.pid)
        assert set_tree_nice(7, pid=parent.pid)  # raising it needs no privilege
        seen = {(p, t): _nice(p, t) for p in pids for t in threads_of(p)}
        assert len(seen) >= 4 and set(seen.values()) == {7}, seen
    finally:
        subprocess.run(["pkill", "-KILL", "-s", str(parent.pid)], check=False)
        parent.wait(10)


@pytest.mark.slow  # it starts processes
def test_the_keeper_sets_back_a_process_that_set_its_own_value() -> None:
    """As Chromium does with its renderers: a process under the tree raises its own nice value; the keeper sets it
    back within its period (lowering a value needs the privilege: without it, the keeper says it is not allowed)."""
    parent = subprocess.Popen([sys.executable, "-c", TREE, "parent", TREE], start_new_session=True)
    keeper = None
    try:
        pids = _tree(parent.pid)
        keeper = NiceKeeper(-2, pid=parent.pid, every=0.2).start()
        if os.geteuid() != 0 and not keeper.allowed:  # no privilege: it holds nothing, and says so
            assert keeper._thread is None
            return
        assert keeper.allowed
        child_tid = threads_of(pids[1])[-1]
        os.setpriority(os.PRIO_PROCESS, child_tid, 6)  # the child's thread sets its own, as a renderer does
        wait_until(
            lambda: all(_nice(p, t) == -2 for p in pids for t in threads_of(p)),
            timeout=10,
            what="every thread back at -2",
            seen=lambda: {(p, t): _nice(p, t) for p in pids for t in threads_of(p)},
        )
        keeper.stop()
        os.setpriority(os.PRIO_PROCESS, child_tid, 6)
        assert _nice(pids[1], child_tid) == 6  # stopped: nothing holds it
    finally:
        if keeper is not None:
            keeper.stop()
        subprocess.run(["pkill", "-KILL", "-s", str(parent.pid)], check=False)
        parent.wait(10)
