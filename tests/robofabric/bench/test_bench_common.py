"""The benchmarks' shared helpers: children ended together, by pid; percentiles of nothing are NaN."""

from __future__ import annotations

import math
import signal
import subprocess
import sys

import pytest

from robofabric.bench.common import end_processes, pct

SLEEPER = [sys.executable, "-c", "import time; time.sleep(60)"]
DEAF = [
    sys.executable,
    "-c",
    "import signal, sys, time; signal.signal(signal.SIGTERM, signal.SIG_IGN); print('ready', flush=True); time.sleep(60)",
]


@pytest.mark.slow  # starts and ends child processes
def test_end_processes_signals_all_first_then_kills_the_deaf_within_one_timeout():
    procs = [
        subprocess.Popen(SLEEPER),
        subprocess.Popen(SLEEPER),
        subprocess.Popen(DEAF, stdout=subprocess.PIPE, text=True),
    ]
    try:
        assert procs[2].stdout.readline().strip() == "ready"  # its SIGTERM handler is in place
        done = subprocess.Popen(SLEEPER)
        done.kill()
        done.wait()
        codes = end_processes([*procs, done], timeout=1.0)
        assert codes == [-signal.SIGTERM, -signal.SIGTERM, -signal.SIGKILL, -signal.SIGKILL]
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()


def test_pct_of_nothing_is_nan():
    assert math.isnan(pct([], 99))
    assert pct([1.0, 2.0, 3.0], 50, 1e3) == 2000.0


def test_a_busy_box_and_a_process_waiting_for_its_cpu_are_read_from_proc():
    import os
    import time

    from robofabric.bench.common import box_idle_s, proc_sched_s, proc_waited_s

    total0, idle0 = box_idle_s()
    waited0 = proc_waited_s(os.getpid())
    sched0 = proc_sched_s(os.getpid())
    spin = time.monotonic() + 0.3
    while time.monotonic() < spin:  # some CPU of this process between the readings
        pass
    total1, idle1 = box_idle_s()
    assert total1 > total0 and idle1 >= idle0 and idle1 - idle0 <= total1 - total0
    assert waited0 >= 0 and proc_waited_s(os.getpid()) >= waited0
    sched1 = proc_sched_s(os.getpid())
    assert sched0 is not None and sched1 is not None
    assert sum(sched1) - sum(sched0) >= 0.2  # the 0.3 s spin, running or waiting for a CPU (run 51: it ran 0.18 s)
    assert math.isnan(proc_waited_s(2**22 + 12345)) and proc_sched_s(2**22 + 12345) is None  # a process not there
