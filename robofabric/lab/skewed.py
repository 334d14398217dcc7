"""Run a Python module on a host whose wall clock is shifted by libfaketime: ``python -m robofabric.lab.skewed MODULE ARGS``.

Debian's libfaketime 0.9.10 cannot shift only the wall clock of a threaded Python cleanly: faking the
monotonic clock too hangs every ``threading.Event.wait`` (``pthread_cond_timedwait``), and leaving it
alone (``FAKETIME_DONT_FAKE_MONOTONIC=1``, what a machine with a wrong clock has) makes ``time.sleep``
fail with EINVAL (its absolute ``clock_nanosleep`` on the monotonic clock is mis-translated). This
wrapper replaces ``time.sleep`` by a ``select`` timeout of the same length, which libfaketime leaves
alone, and then runs the module as ``__main__``. Nothing that reads a clock is changed.
"""

from __future__ import annotations

import runpy
import select
import sys
import time


def _sleep(seconds: float) -> None:
    if seconds < 0:
        raise ValueError("sleep length must be non-negative")
    select.select([], [], [], seconds)


def main() -> None:
    if len(sys.argv) < 2:
        raise SystemExit("usage: python -m robofabric.lab.skewed MODULE [ARGS...]")
    time.sleep = _sleep
    module = sys.argv[1]
    sys.argv = [module, *sys.argv[2:]]
    runpy.run_module(module, run_name="__main__", alter_sys=True)


if __name__ == "__main__":
    main()
