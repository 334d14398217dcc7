"""Loaded by every Python process started with this folder on PYTHONPATH: at its exit, one line of its CPU.

Each line (tab-separated): CPU seconds (user + system, its own threads), wall seconds, the pytest test it ran
under (``PYTEST_CURRENT_TEST``, inherited from the test that started it; ``-`` outside a test) and its argv.
A process killed without running its exit handlers (SIGKILL, or SIGTERM where it set no handler of its own) is
not counted: robofabric's peers end on SIGTERM cleanly (``fabric.session.shutdown_event``). See README.md."""

import atexit
import os
import sys
import time

_LOG = os.environ.get("RF_CPU_LOG")
if _LOG:
    _t0 = time.time()

    def _write() -> None:
        t = os.times()
        test = os.environ.get("PYTEST_CURRENT_TEST", "-").split(" ")[0]
        with open(_LOG, "a") as f:
            f.write(f"{t.user + t.system:.3f}\t{time.time() - _t0:.2f}\t{test}\t{' '.join(sys.argv[:5])[:200]}\n")

    atexit.register(_write)
