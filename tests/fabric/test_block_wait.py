"""A subscriber that stops reading (a student's laptop paused) loses its own link, not its publishers'.

The router routes each sample on the thread that reads its publisher's link. A blocking sample (a map, an ownership
record: fabric.publishers) for a subscriber whose queue is full waits there; with zenoh's default of 5 s the router
read nothing more from the publisher meanwhile and dropped it when its 2 s lease ran out (CI: the compute peer lost
its link while a paused student's map was on its way to him). Real sessions: an in-process router, the publisher in
this process, the paused subscriber a process of its own."""

from __future__ import annotations

import json
import signal
import sys
import threading
import time

import numpy as np
import pytest

from fabric import keys
from fabric.config import ZENOH_DEFAULT_BLOCK_WAIT_US, FabricConfig
from fabric.interfaces import OccupancyGrid
from robofabric.testing import wait_until

BLOCK_WAIT = "transport/link/tx/queue/congestion_control/block/wait_before_close"


def test_a_router_waits_half_its_lease_to_queue_a_blocking_sample_and_clients_keep_zenohs_wait(tmp_path):
    def wait_us(conf: FabricConfig) -> int:
        return int(json.loads(conf.zenoh_config().get_json(BLOCK_WAIT)))

    assert wait_us(FabricConfig(profile="embedded")) == 1_000_000
    assert wait_us(FabricConfig(profile="embedded", lease_ms=4000)) == 2_000_000
    assert wait_us(FabricConfig(profile="client")) == ZENOH_DEFAULT_BLOCK_WAIT_US
    own = tmp_path / "zenoh.json5"
    own.write_text(
        json.dumps(
            {
                "transport": {
                    "link": {"tx": {"queue": {"congestion_control": {"block": {"wait_before_close": 3_000_000}}}}}
                }
            }
        )
    )
    assert wait_us(FabricConfig(profile="embedded", config_file=str(own))) == 3_000_000  # a file's choice stays


SUBSCRIBER = """
import sys, time
from robofabric.testing import client
fab = client(sys.argv[1], int(sys.argv[2]), kind="user", peer_id="paused")
fab.subscribe_raw(sys.argv[3], lambda s: None)
print("subscribed", flush=True)
while True:
    time.sleep(1)
"""


@pytest.mark.slow
def test_a_paused_subscriber_loses_its_link_and_the_publisher_keeps_its(world, router, connect, procs):
    pub = connect("compute", "mapper")
    sub = procs.start([sys.executable, "-c", SUBSCRIBER, world, str(router[1]), keys.world_all(world)], name="sub")
    wait_until(lambda: ("user", "paused") in router[0].live_peers("user"), timeout=60, what="the subscriber's token")
    wait_until(
        lambda: "subscribed" in procs.output(sub), timeout=30, what="the subscriber", seen=lambda: procs.output(sub)
    )
    junk = keys.robot_scan(world, "base1")  # dropped when a queue is full: fills the paused one's
    grid = OccupancyGrid(0.05, np.zeros(3), np.zeros((200, 200), np.uint8))
    longest, stop = [0.0], threading.Event()

    def publish() -> None:
        for _ in range(400):  # bounded: 8 s at most
            if stop.is_set():
                return
            for _ in range(20):
                pub.put_raw(junk, b"x" * 16_000)
            t = time.monotonic()
            pub.publish(keys.map_key(world, "map"), grid)  # blocks while the paused one's queue is full
            longest[0] = max(longest[0], time.monotonic() - t)
            time.sleep(0.02)

    wait_until(lambda: (pub.publish(keys.map_key(world, "map"), grid), True)[1], what="the publisher's first map")
    sub.send_signal(signal.SIGSTOP)
    worker = threading.Thread(target=publish, daemon=True)
    worker.start()
    try:
        wait_until(
            lambda: ("user", "paused") not in router[0].live_peers("user"),
            timeout=30,
            interval=0.25,
            what="the router dropping the paused subscriber",
        )
        dropped_at = time.monotonic()
        wait_until(lambda: time.monotonic() - dropped_at > 2.5 or not worker.is_alive(), what="a lease after it")
    finally:
        stop.set()
        sub.send_signal(signal.SIGCONT)
        worker.join(30)
    assert pub.counters["links_lost"] == 0, (
        f"the publisher lost its link; its longest map publication took {longest[0]:.2f} s"
    )
    assert ("compute", "mapper") in router[0].live_peers("compute")
