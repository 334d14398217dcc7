"""A test's priority reaches every thread of its process and of the processes under it (robofabric/priority.py)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from robofabric.priority import set_tree_nice, threads_of
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


@pytest.mark.slow  # it starts processes
def test_every_thread_of_a_process_and_of_its_children_gets_the_nice_value() -> None:
    parent = subprocess.Popen([sys.executable, "-c", TREE, "parent", TREE], start_new_session=True)
    try:
        from robofabric.hang_watch import children_of

        def tree() -> list[int] | None:
            kids = children_of().get(parent.pid, [])
            ok = kids and len(threads_of(parent.pid)) >= 2 and len(threads_of(kids[0])) >= 2
            return [parent.pid, kids[0]] if ok else None

        pids = wait_until(tree, timeout=30, what="the process, its child and their threads")
        assert set_tree_nice(7, pid=parent.pid)  # raising it needs no privilege
        seen = {(p, t): _nice(p, t) for p in pids for t in threads_of(p)}
        assert len(seen) >= 4 and set(seen.values()) == {7}, seen
    finally:
        subprocess.run(["pkill", "-KILL", "-s", str(parent.pid)], check=False)
        parent.wait(10)
