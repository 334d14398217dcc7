"""The objects' adoption built on its own: a real fabric, a recording server in the host's place, the stop flag
and a fake clock passed in, no ReplicaHost.

It asks ``srv/world`` which sims serve a part of the world; when none describes the scene objects and this sim
has the lowest id, it asks its server to serve them, and says so with the time it took on the clock it was given."""

from __future__ import annotations

import threading

import numpy as np

from fabric import keys
from fabric.interfaces import ObjectInfo, WorldInfo
from robofabric.testing import wait_until
from sim_peer.replica.adoption import ObjectAdoption


class RecordingServer:
    """The host's side of the seam (:class:`~sim_peer.replica.adoption.ObjectsServer`): answers as told, records
    the adoptions asked of it, and moves the fake clock as serving again would take time."""

    def __init__(self, clock: list[float], *, serves: bool = False, term: int | None = 4) -> None:
        self.clock, self.serves, self.term = clock, serves, term
        self.adopted = 0

    def serves_objects(self) -> bool:
        return self.serves

    def scene_objects(self) -> tuple[str, ...]:
        return ("box", "goal")

    def adopt_objects(self) -> int | None:
        self.adopted += 1
        self.clock[0] += 0.25  # serving again took 250 ms on the fake clock
        if self.term is not None:
            self.serves = True
        return self.term


def _serve_world(fab, *, objects: bool) -> None:
    """Answer ``srv/world`` as a sim serving a part of the world does, describing scene objects or not."""
    described = (ObjectInfo("box", "ik_target", "scene", np.zeros(3), np.array([1.0, 0, 0, 0])),) if objects else ()

    def answer(key: str, request: object) -> WorldInfo:
        return WorldInfo(fab.world, "scene", 0.002, {}, (), described, header=fab.header(key))

    fab.rpc.serve(keys.srv(fab.world, "world"), answer)


def _adoption(fab, server, clock, stopping=None, after_s=0.05):
    said: list[str] = []
    part = ObjectAdoption(
        fab,
        server,
        stopping=stopping or threading.Event(),
        announce=said.append,
        clock=lambda: clock[0],
        after_s=after_s,
    )
    return part, said


def _wait_listed(fab, n: int) -> None:
    """Until ``n`` sims answer ``srv/world`` (a queryable takes a moment to reach the router)."""
    wait_until(
        lambda: len(fab.rpc.query(keys.srv(fab.world, "world"), timeout=1.0, all_replies=True)) >= n,
        timeout=30,
        what=f"{n} sims on srv/world",
    )


def test_the_lowest_sim_adopts_orphaned_objects_and_announces_on_its_clock(connect):
    a, b = connect("sim", "sim-a"), connect("sim", "sim-b")
    _serve_world(a, objects=False)
    _serve_world(b, objects=False)
    _wait_listed(a, 2)
    clock = [100.0]
    server = RecordingServer(clock)
    part, said = _adoption(a, server, clock)
    assert part.adopt_if_orphaned()
    assert server.adopted == 1
    assert said == [
        "sim sim-a: no sim serves the scene objects any more; serving box, goal with my robots (term 4) in 250 ms"
    ]
    # the other sim is not the lowest: it asks its server nothing
    other = RecordingServer(clock)
    assert not _adoption(b, other, clock)[0].adopt_if_orphaned() and other.adopted == 0


def test_no_adoption_while_a_sim_describes_the_objects(connect):
    a, b = connect("sim", "sim-a"), connect("sim", "sim-b")
    _serve_world(a, objects=False)
    _serve_world(b, objects=True)
    _wait_listed(a, 2)
    clock = [0.0]
    server = RecordingServer(clock)
    part, said = _adoption(a, server, clock)
    assert not part.adopt_if_orphaned()
    assert server.adopted == 0 and said == []


def test_a_server_that_no_longer_serves_declines_and_nothing_is_announced(connect):
    a = connect("sim", "sim-a")
    _serve_world(a, objects=False)
    _wait_listed(a, 1)
    clock = [0.0]
    declining = RecordingServer(clock, term=None)  # stepped down meanwhile, say
    part, said = _adoption(a, declining, clock)
    assert not part.adopt_if_orphaned()
    assert declining.adopted == 1 and said == []


def test_a_departure_adopts_after_the_wait_once_and_a_server_of_the_objects_starts_none(connect):
    a = connect("sim", "sim-a")
    _serve_world(a, objects=False)
    _wait_listed(a, 1)
    clock = [0.0]
    server = RecordingServer(clock)
    part, said = _adoption(a, server, clock)
    part.soon()
    part.soon()  # a second departure joins the wait under way

    def adopted() -> bool:
        if not server.adopted and not part._watch.running:
            part.soon()  # the wait ended without adopting (srv/world unanswered on a loaded box): another departure
        return bool(server.adopted == 1 and said)

    wait_until(adopted, timeout=30, what="the objects adopted")
    wait_until(lambda: not part._watch.running, timeout=30, what="the wait ended")
    assert server.adopted == 1
    part.soon()  # serving the objects now: no wait starts
    assert not part._watch.running and server.adopted == 1


def test_a_stopping_host_ends_the_wait_before_looking(connect):
    a = connect("sim", "sim-a")
    clock, stopping = [0.0], threading.Event()
    server = RecordingServer(clock)
    part, said = _adoption(a, server, clock, stopping, after_s=30.0)
    part.soon()
    assert part._watch.running
    stopping.set()
    wait_until(lambda: not part._watch.running, timeout=30, what="the wait ended")
    assert server.adopted == 0 and said == []
