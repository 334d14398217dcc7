"""The API behaves like a library: scripts exit without close(), joining waits for the sim,
queued requests wait their turn, non-owners are told at once. Real router, real sim, real scripts."""

from __future__ import annotations

import re
import subprocess
import sys
import textwrap
import time
import uuid

import numpy as np
import pytest

import user_peer
from user_peer.recordings import read_info
from fabric.session import Fabric
from robofabric.testing import ProcessGroup, free_port, robofabric_cmd, router_config, wait_until
from user_peer.api import World

pytestmark = pytest.mark.slow


@pytest.fixture
def user(live):
    made: list[World] = []

    def make(name: str) -> World:
        w = user_peer.connect(
            world=live[0], connect=f"tcp/127.0.0.1:{live[1]}", user=name, timeout=10.0, join_timeout=60.0
        )
        made.append(w)
        return w

    yield make
    for w in made:
        w.close()


def script(procs: ProcessGroup, name: str, body: str) -> subprocess.Popen:
    """A user's script as its own interpreter (what `python script.py` does)."""
    return procs.start([sys.executable, "-c", textwrap.dedent(body)], name=name)


def printed(procs: ProcessGroup, proc: subprocess.Popen, marker: str, timeout: float = 90.0) -> None:
    wait_until(
        lambda: marker in procs.output(proc) or proc.poll() is not None,
        timeout=timeout,
        what=f"{marker!r} from {proc.name}",
        seen=lambda: procs.output(proc)[-2000:],
    )
    assert marker in procs.output(proc), procs.output(proc)[-2000:]


def test_script_that_never_closes_exits_and_releases_its_robot(live, user):
    world, port, procs = live
    bob = user("bob")
    events: list = []
    bob.on("event/own/arm1", lambda k, ev: events.append(ev))
    carol = script(
        procs,
        "carol",
        f"""
        import user_peer
        w = user_peer.connect(world={world!r}, connect=["tcp/127.0.0.1:{port}"], user="carol")
        arm = w.robot("arm1")
        arm.request()
        print("owned", flush=True)
    """,
    )
    printed(procs, carol, "owned")
    t_owned = time.monotonic()
    carol.wait(timeout=30)  # the issue: without the fix it never exits
    exited_after = time.monotonic() - t_owned
    assert carol.returncode == 0, procs.output(carol)[-2000:]
    assert exited_after < 5.0, f"the script took {exited_after:.1f} s to exit after its last line"
    # the release is explicit (reason "released"), not the token loss ("left") or a lease expiry
    wait_until(
        lambda: any(e.kind == "own_released" and e.user == "carol" for e in events),
        timeout=10,
        what="carol's release",
        seen=lambda: [(e.kind, e.user, e.reason) for e in events],
    )
    rel = [e for e in events if e.kind == "own_released" and e.user == "carol"]
    assert rel[0].reason == "released", [(e.kind, e.user, e.reason) for e in events]
    assert not any(e.kind == "own_expired" for e in events)


def test_joining_waits_for_a_sim_that_starts_later(tmp_path):
    """A script started one second before the sim (as a launch file may do) succeeds: the sim is started
    only once the script is inside connect(), a second later, and connect() reports that it waited."""
    world = f"t{uuid.uuid4().hex[:8]}"
    port = free_port()
    with Fabric(router_config(world, port), kind="router", peer_id="router"), ProcessGroup(tmp_path) as procs:
        early = script(
            procs,
            "early",
            f"""
            import time, user_peer
            print("joining", flush=True)
            t0 = time.monotonic()
            w = user_peer.connect(world={world!r}, connect="tcp/127.0.0.1:{port}", user="early", join_timeout=90)
            print("joined after", round(time.monotonic() - t0, 2), "s", flush=True)
            print("robots", w.robots(), flush=True)
        """,
        )
        printed(procs, early, "joining")
        time.sleep(1.0)  # the scenario itself: the sim starts one second after the script began to join
        procs.start(
            robofabric_cmd("sim", "--scene", "combined", "--world", world, "--connect", f"tcp/127.0.0.1:{port}"),
            name="sim",
        )
        early.wait(timeout=120)
        out = procs.output(early)
        assert early.returncode == 0, out[-2000:]
        assert "robots ['arm1', 'base1']" in out, out[-2000:]
        waited = re.search(r"joined after ([0-9.]+) s", out)
        assert waited and float(waited.group(1)) >= 1.0, out[-2000:]  # connect() waited for the sim, not returned early


def test_joining_an_empty_world_says_how_long_it_waited(live):
    world, port, _ = live
    with pytest.raises(user_peer.Timeout) as exc:
        user_peer.connect(world=world + "x", connect=f"tcp/127.0.0.1:{port}", user="dan", join_timeout=1.5)
    m = re.search(r"after ([0-9.]+) s of waiting", exc.value.reason)
    assert m and float(m.group(1)) >= 1.5, exc.value.reason
    assert "no sim peer alive" in exc.value.reason and "srv/world" in exc.value.reason


MOVER = """
    import time, user_peer
    w = user_peer.connect(world={world!r}, connect="tcp/127.0.0.1:{port}", user="dave")
    arm = w.robot("arm1")
    arm.request(timeout=30)
    far = [[1.2, 0.4, -0.4, 1.0, 0.8, 1.5], [-1.2, -0.4, 0.4, -1.0, -0.8, -1.5]]
    q = arm.wait_for("joints").q
    i = 0 if max(abs(a - b) for a, b in zip(q, far[0])) > max(abs(a - b) for a, b in zip(q, far[1])) else 1  # the far one
    first = i
    end = time.monotonic() + {seconds}
    # never reach a target: a new one every 0.3 s keeps the arm in motion (a still arm is handed over at once)
    while time.monotonic() < end:
        arm.move_joints(far[i % 2], wait=False, speed_scale=0.2)
        if i == first:
            w.latest.wait_for(lambda: arm.record.state == "moving", 10)
            print("moving", arm.record.state, arm.record, [(e.kind, e.reason) for e in w.events][-5:], flush=True)
        i += 1
        time.sleep(0.3)
    print("done", flush=True)
"""


def test_queued_request_waits_for_the_owner_to_leave(live, user):
    world, port, procs = live
    bob = user("bob")
    arm = bob.robot("arm1")
    dave = script(procs, "dave", MOVER.format(world=world, port=port, seconds=12))
    printed(procs, dave, "moving moving")
    wait_until(
        lambda: arm.owner == "dave" and arm.record.state == "moving",
        timeout=10,
        what="bob's replica: dave, moving",
        seen=lambda: arm.record,
    )
    # a non-owner's command is refused at once, naming the owner (not after the move's timeout)
    t0 = time.monotonic()
    with pytest.raises(user_peer.NotOwner, match="owner: dave"):
        arm.move_joints(np.zeros(6), timeout=60)
    assert time.monotonic() - t0 < 5.0
    # without wait: refused with the authority's reason
    with pytest.raises(user_peer.NotOwner, match="in motion, owned by dave"):
        arm.request()
    # with wait: queued; the place becomes ownership when dave's script ends (it never calls close())
    epoch = arm.request(wait=True, timeout=60)
    assert dave.poll() is not None or "done" in procs.output(dave), "granted while dave still ran"
    assert arm.is_owner and arm.record.epoch == epoch
    assert "owned by you" in repr(arm)
    # the world's repr shows what the world holds, its description once it came (beside two CPU hogs, not yet)
    wait_until(lambda: "arm1" in repr(bob), timeout=30, what="arm1 in the world's repr", seen=lambda: repr(bob))
    arm.release()


def test_queued_request_times_out_and_leaves_the_queue(live, user):
    world, port, procs = live
    erin = user("erin")
    arm = erin.robot("arm1")
    dave = script(procs, "dave", MOVER.format(world=world, port=port, seconds=20))
    printed(procs, dave, "moving moving")
    wait_until(lambda: arm.owner == "dave", timeout=10, what="erin's replica: dave", seen=lambda: arm.record)
    t0 = time.monotonic()
    with pytest.raises(user_peer.Timeout, match=r"not granted to erin after [0-9.]+ s of waiting .*left the queue"):
        arm.request(wait=True, timeout=1.5)
    assert time.monotonic() - t0 >= 1.5
    wait_until(
        lambda: "erin" not in erin.ownership.fetch("arm1", timeout=2.0).queue,
        timeout=10,
        what="erin out of the queue",
        seen=lambda: arm.record,
    )
    procs.kill(dave)


EVERYTHING = """
    import time
    from pathlib import Path
    from fabric import keys
    from robofabric.testing import client_config, router_config
    from fabric.session import Fabric
    from fabric.recording import Recorder
    from robofabric.recording.live_convert import LiveConverter, open_exporter
    from sim_peer.cli import make_gate
    from sim_peer.serving.peer import SimPeer
    from sim_peer.physics.world import SimWorld
    from compute_peer.peer import ComputeOptions, ComputePeer
    from user_peer.api import World
    from user_peer.viewer import Viewer, ViewerOptions

    w, port, out = {world!r}, {port}, Path({out!r})
    router = Fabric(router_config(w, port), kind="router", peer_id="router")
    sim_fab = Fabric(client_config(w, port), kind="sim", peer_id="sim")
    sim_world = SimWorld("combined")
    SimPeer(sim_fab, sim_world, gate=make_gate(sim_fab, sim_world, True)).start()
    ComputePeer(Fabric(client_config(w, port), kind="compute", peer_id="compute"), ComputeOptions(streams=[("arm1", "target")])).discover()
    viewer = Viewer(client_config(w, port), ViewerOptions(save=out / "view.rrd"))
    viewer.start()
    Recorder(Fabric(client_config(w, port), kind="recorder", peer_id="rec"), out / "rec.mcap").start()
    fox = open_exporter("foxglove", out / "live-foxglove.mcap", scene="combined")  # what record --to foxglove runs
    LiveConverter(Fabric(client_config(w, port), kind="recorder", peer_id="conv"), fox, [keys.world_all(w)]).start()
    user = World(client_config(w, port), "frank", timeout=10.0, join_timeout=60.0)
    arm = user.robot("arm1")
    arm.request()
    arm.move_joints([0.1, 0, 0, 0, 0, 0], timeout=30)
    end = time.monotonic() + 1.0
    while time.monotonic() < end:  # a second of windows drawn (Viewer.draw: one window)
        viewer.draw()
        time.sleep(0.1)
    print("everything running", flush=True)
"""


def test_nothing_the_fabric_starts_keeps_a_script_alive(tmp_path):
    """A router, a sim peer with its authority, a compute peer, a viewer, a recorder, a live converter to
    Foxglove and a user that owns a robot, all in one script that closes none of them: it exits, and the
    viewer's, the recorder's and the converter's files are complete (footer and summary written)."""
    world = f"t{uuid.uuid4().hex[:8]}"
    with ProcessGroup(tmp_path) as procs:
        p = script(procs, "everything", EVERYTHING.format(world=world, port=free_port(), out=str(tmp_path)))
        printed(procs, p, "everything running", timeout=120)
        t0 = time.monotonic()
        p.wait(timeout=60)
        took = time.monotonic() - t0
        assert p.returncode == 0, procs.output(p)[-3000:]
        assert took < 10.0, f"took {took:.1f} s to exit after its last line"
    assert (tmp_path / "view.rrd").stat().st_size > 10_000
    for name in ("rec.mcap", "live-foxglove.mcap"):
        info = read_info(tmp_path / name)
        assert info.complete and info.messages > 10, (name, info.status, info.detail, info.messages)
