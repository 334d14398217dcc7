"""A process's standstills (fabric.standstill) on a clock passed in, and the query a client asks as it wakes from a
pause past its lease: answered, not "nobody serves it" (a real router and a real paused process)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap

import pytest

from fabric import keys
from fabric.interfaces import Twist
from fabric.rate import FakeClock
from fabric.session import Fabric
from fabric.standstill import Standstill
from robofabric.testing import client, free_port, router_config, wait_until


def test_a_gap_between_ticks_is_the_latest_standstill_and_one_going_on_ends_now():
    clock = FakeClock(100.0)
    still = Standstill(clock.now, thread=False)
    for _ in range(20):  # a process that runs: ticks 0.1 s apart
        clock.jump(0.1)
        still.tick()
    assert still.last() == (float("-inf"), float("-inf"))
    clock.jump(3.0)  # stopped: no tick for 3 s, and the caller runs before the thread ticks again
    assert still.last() == pytest.approx((102.0, 105.0))
    still.tick()
    clock.jump(0.1)
    still.tick()
    assert still.last() == pytest.approx((102.0, 105.0))  # kept as the latest


CHILD = textwrap.dedent(
    """
    import sys, time
    from fabric.interfaces import Twist
    from robofabric.testing import client
    world, port, key = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    c = client(world, port, kind="user", peer_id="sleeper")
    answer = c.rpc.call(key, Twist(1.0, 0.0), timeout=10.0).v
    last = time.monotonic()  # before the test hears the answer: a stop from then on is a jump of this clock
    print(answer, flush=True)  # served
    while True:  # until this process is stopped and woken, then ask at once
        now = time.monotonic()
        if now - last > 1.5:
            break
        last = now
        time.sleep(0.01)
    try:
        print("woke:", c.rpc.call(key, Twist(2.0, 0.0), timeout=10.0).v, flush=True)
    except Exception as exc:
        print("woke:", exc, flush=True)
    c.close()
    """
)


@pytest.mark.slow  # a process, stopped past its lease
def test_a_query_asked_as_a_client_wakes_from_a_pause_past_its_lease_is_answered(world):
    port = free_port()
    router = Fabric(router_config(world, port), kind="router", peer_id="router")
    server = client(world, port, kind="compute", peer_id="c1")
    key = keys.srv(world, "fk", "arm1")
    server.rpc.serve(key, lambda k, req: Twist(req.v * 2, 0.0, header=server.header(k)), expected=Twist)
    child = subprocess.Popen(
        [sys.executable, "-c", CHILD, world, str(port), key],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        assert child.stdout is not None
        assert child.stdout.readline().strip() == "2.0"
        child.send_signal(signal.SIGSTOP)
        try:  # stopped until the router has dropped its link (its lease: 2 s)
            wait_until(
                lambda: ("user", "sleeper") not in router.live_peers("user"),
                timeout=30,
                interval=0.25,
                what="the router dropping the stopped client",
            )
        finally:
            child.send_signal(signal.SIGCONT)
        out, _ = child.communicate(timeout=60)
        woke = next((line for line in out.splitlines() if line.startswith("woke:")), out[-2000:])
        assert woke == "woke: 4.0", out[-2000:]  # before: "nobody serves it", at once
    finally:
        if child.poll() is None:
            os.kill(child.pid, signal.SIGKILL)
            child.wait(timeout=10)
        server.close()
        router.close()
