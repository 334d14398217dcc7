"""fabric.exit: closers run before Python joins non-daemon threads, newest first, each once."""

from __future__ import annotations

import gc
import subprocess
import sys
import textwrap
import weakref

import pytest

from fabric.exit import at_exit


def _run(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, timeout=60)


@pytest.mark.slow
def test_closers_run_before_non_daemon_threads_are_joined_newest_first():
    out = _run("""
        import threading
        from fabric.exit import at_exit
        stop = threading.Event()
        threading.Thread(target=stop.wait).start()  # non-daemon: what zenoh's callback threads are
        at_exit(lambda: print("first registered", flush=True))
        at_exit(lambda: (print("second registered", flush=True), stop.set()))
        cancel = at_exit(lambda: print("cancelled", flush=True))
        cancel()
        print("end of script", flush=True)
    """)
    assert out.returncode == 0, out.stderr
    assert out.stdout.splitlines() == ["end of script", "second registered", "first registered"]


@pytest.mark.slow
def test_a_failing_closer_does_not_stop_the_others():
    out = _run("""
        from fabric.exit import at_exit
        at_exit(lambda: print("ran", flush=True))
        at_exit(lambda: 1 / 0)
    """)
    assert out.returncode == 0 and out.stdout.splitlines() == ["ran"], (out.stdout, out.stderr)


def test_a_bound_method_is_held_weakly():
    class Thing:
        closed = 0

        def close(self) -> None:
            Thing.closed += 1

    t = Thing()
    alive = weakref.ref(t)
    cancel = at_exit(t.close)
    del t
    gc.collect()
    assert alive() is None  # registering its close() did not keep it alive
    cancel()
    assert Thing.closed == 0
