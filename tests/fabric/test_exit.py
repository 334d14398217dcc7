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


@pytest.mark.slow
def test_a_forked_child_closes_what_is_registered_in_it_before_its_threads_are_joined():
    out = _run("""
        import os, threading
        from fabric.exit import at_exit
        at_exit(lambda: print("inherited", flush=True))
        pid = os.fork()
        if pid == 0:
            stop = threading.Event()
            threading.Thread(target=stop.wait, args=(20,)).start()  # non-daemon: only a closer ends it at once (20 s at most:
            # a child that closed nothing still ends by itself, and then has not printed its line)
            at_exit(lambda: (print("child's own", flush=True), stop.set()))
            raise SystemExit(0)
        _, status = os.waitpid(pid, 0)
        print("child exited", os.waitstatus_to_exitcode(status), flush=True)
    """)
    assert out.returncode == 0, out.stderr
    assert out.stdout.splitlines() == ["child's own", "inherited", "child exited 0", "inherited"], (
        out.stdout,
        out.stderr,
    )
