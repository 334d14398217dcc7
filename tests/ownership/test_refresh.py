"""Refresh on demand: asks before it is enabled or after it is closed run nothing; a burst of asks while the
job runs makes it run once more on the same thread, never a thread each."""

from __future__ import annotations

import threading

from robofabric.testing import wait_until
from ownership.refresh import Refresher


def test_asks_while_running_coalesce_into_one_more_run_on_one_thread():
    gate, runs, threads = threading.Event(), [], set()

    def job() -> None:
        runs.append(1)
        threads.add(threading.current_thread().name)
        gate.wait(5.0)

    r = Refresher(job, name="refresh-test")
    r.ask()
    assert runs == []  # not enabled yet: the first query is the constructor's
    r.enable()
    r.ask()
    wait_until(lambda: len(runs) == 1, what="the first run", seen=lambda: runs)
    for _ in range(50):
        r.ask()
    gate.set()
    wait_until(lambda: len(runs) == 2, what="one more run for the burst", seen=lambda: runs)
    wait_until(lambda: not any(t.name == "refresh-test" for t in threading.enumerate()), what="the thread gone")
    assert len(runs) == 2 and threads == {"refresh-test"}
    r.close()
    r.ask()
    assert not any(t.name == "refresh-test" for t in threading.enumerate()) and len(runs) == 2
