"""The freeze guard and the deaf stop built on their own: a real fabric, the election's shell and the shard as small
recording parts, the stop flag and a fake clock passed in, no ReplicaHost.

A primary frozen with no rival publishes again at once; one with a rival of its shard asks ``srv/state`` who holds
it and tells the election the term it heard, then publishes again under a new term. A primary cut off holds its
robots and lets them go once it hears again; a sim that serves nothing is not looked at."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from fabric import keys
from fabric.interfaces import Header, RobotState, WorldState
from robofabric.testing import wait_until
from sim_peer.replica import election as el
from sim_peer.replica import freeze_guard
from sim_peer.replica import hearing_rule as hr
from sim_peer.replica.deaf_stop import REASON, DeafStop
from sim_peer.replica.freeze_guard import FreezeGuard


class Electing:
    """The election's shell as the guard sees it: a primary, the sims gone since a time, what it was told."""

    def __init__(self, live: set[str]) -> None:
        self.role, self.live = el.PRIMARY, live
        self.told: list[tuple[str, int]] = []
        self.steps: list[el.Event] = []

    def gone_since(self, began: float) -> set[str]:
        return set(self.live)

    def heard(self, source: str, term: int) -> None:
        self.told.append((source, term))

    def step(self, ev: el.Event) -> None:
        self.steps.append(ev)


class Shard:
    """The shard as the guard reads it: every sim is of it, and every state with arm1 is its."""

    def view(self, live: frozenset[str]) -> frozenset[str]:
        return live

    def about_mine(self, state: object) -> bool:
        return isinstance(state, WorldState) and any(r.id == "arm1" for r in state.robots)


def _guard(fab, roles: Electing, said: list[str], gap: float = 0.5) -> FreezeGuard:
    return FreezeGuard(
        fab, roles=roles, shard=Shard(), stopping=threading.Event(), announce=said.append, gap=gap, clock=lambda: 100.0
    )


def test_a_primary_frozen_with_no_rival_publishes_again_at_once(connect):
    fab = connect("sim", "sim-a")
    said: list[str] = []
    roles = Electing({"sim-a"})
    fab.stamp.muzzle()
    _guard(fab, roles, said).on_freeze(0.8)
    assert not fab.stamp.muzzled and roles.steps == [] and roles.told == []
    assert said[0].startswith("sim sim-a: paused 0.8 s with no other sim in the world; publishing again")


def _muzzled_beside_a_rival(connect, delay: list[float] | None = None):
    """sim-a, muzzled as a freeze leaves it, beside sim-b, whose ``srv/state`` says it holds arm1 at term 1 (its token
    and its answer both reached sim-a's router). sim-b answers ``delay[0]`` seconds late, read at each ask."""
    fab, rival = connect("sim", "sim-a"), connect("sim", "sim-b")
    arm = RobotState("arm1", "arm", np.zeros(1), np.zeros(1), np.zeros(1))
    late = delay if delay is not None else [0.0]

    def answer(key: str, request: object) -> WorldState:
        time.sleep(late[0])  # as a starved process answers
        return WorldState(0.0, 0, (arm,), (), header=Header(source="sim-b", term=1))

    rival.rpc.serve(keys.srv(fab.world, "state"), answer)
    wait_until(
        lambda: any(pid == "sim-b" for _, pid in fab.live_peers("sim", timeout=1.0)),
        timeout=30,
        what="the rival's token",
    )
    wait_until(
        lambda: fab.rpc.query(keys.srv(fab.world, "state"), timeout=1.0, expected=WorldState, all_replies=True),
        timeout=30,
        what="the rival's srv/state at the router",
    )
    fab.stamp.muzzle()
    return fab


@pytest.mark.slow  # it listens a lease, muzzled, before it asks
def test_a_primary_frozen_past_the_lease_asks_who_holds_its_shard_and_reasserts(connect):
    fab = _muzzled_beside_a_rival(connect)
    said: list[str] = []
    roles = Electing({"sim-a", "sim-b"})
    gap = fab.config.lease_ms / 1000.0 + 0.01  # past the lease
    _guard(fab, roles, said, gap=0.05).on_freeze(gap)
    # the rival's term, for the election (a lower one: it stays)
    assert roles.told == [("sim-b", 1)], (said, dict(fab.counters))
    assert [type(e) for e in roles.steps] == [el.Resumed] and not fab.stamp.muzzled
    assert said == [f"sim sim-a: frozen {gap:.1f} s, still the authority (term {fab.stamp.term})"]


@pytest.mark.slow  # it listens a lease, muzzled, before it asks
def test_a_rival_that_answers_late_is_waited_for_longer_at_each_look(connect):
    """CI's run at load 7-10 (2026-12-02) saw three one-second looks come back empty while the rival served all along:
    each look waits longer than the one before (1, 2, 4 s)."""
    delay = [0.0]
    fab = _muzzled_beside_a_rival(connect, delay)
    delay[0] = 1.3  # past a one-second wait, within a two-second one
    said: list[str] = []
    roles = Electing({"sim-a", "sim-b"})
    _guard(fab, roles, said, gap=0.05).on_freeze(fab.config.lease_ms / 1000.0 + 0.01)
    assert roles.told == [("sim-b", 1)], (said, dict(fab.counters))  # with 1 s looks all three miss: nobody told
    if not fab.counters["freeze_look_no_reply"]:
        # its first look was answered though the rival took 1.3 s: this process's own timer ran late (a whole run at
        # load, the nineteenth session's run 45), so this run cannot tell the longer looks from one-second ones
        print("the first look was answered: this run cannot tell the longer waits apart", dict(fab.counters))


@pytest.mark.slow  # it listens a lease, muzzled, before it asks
def test_a_rival_whose_token_no_look_finds_is_asked_all_the_same(connect, monkeypatch):
    """A whole run at load 14 (2026-12-02, run 36) saw three looks find no rival's token (``freeze_look_no_token``),
    the rival serving all along: the tokens only say what a miss was, the ask goes out whatever they show."""
    fab = _muzzled_beside_a_rival(connect)
    monkeypatch.setattr(fab, "live_peers", lambda kind="*", timeout=1.0: [])  # as the run's looks found
    said: list[str] = []
    roles = Electing({"sim-a", "sim-b"})
    _guard(fab, roles, said, gap=0.05).on_freeze(fab.config.lease_ms / 1000.0 + 0.01)
    assert roles.told == [("sim-b", 1)], (said, dict(fab.counters))


@pytest.mark.slow  # it listens a lease, muzzled, before it asks
def test_a_rival_its_fence_holds_gone_for_a_moment_is_asked_again(connect, monkeypatch):
    """A stall of the whole process drops every link of it: the primary's fence hears the rival's token go and refuses
    its answers until the going is checked with the router (0.5 s on). Taken for a standby's refusal, that answer left
    the election untold (the suite's run of 2026-12-01): it is asked again."""
    fab = _muzzled_beside_a_rival(connect)
    said: list[str] = []
    roles = Electing({"sim-a", "sim-b"})
    wait_until(lambda: "sim-b" in fab.sim_fence.sims, timeout=30, what="the rival in the fence's sims")
    # Only the check below finds the rival back: a late copy of its token from the watch's history (a loaded box
    # delivered one after the going, and the answer was never refused: the suite's run of 2026-12-01) waits for it.
    seen = fab.sim_fence.sim_seen
    monkeypatch.setattr(fab.sim_fence, "sim_seen", lambda pid: None if pid == "sim-b" else seen(pid))
    fab.sim_fence.sim_left("sim-b")  # its going heard; the check that finds it back comes a moment later
    # Looks enough that a loaded box cannot spend them all: the ask after the refusal timed out too (run 7 of
    # 2026-12-01), and three looks were gone. A refusal taken for an answer still returns at once, untold.
    monkeypatch.setattr(freeze_guard, "EMPTY_LOOKS", 10)
    done = threading.Event()

    def checked_back() -> None:  # as the token watch's check does, once an answer was refused
        while not done.is_set() and fab.counters["stale_authority"] < 1:
            done.wait(0.02)
        seen("sim-b")

    back = threading.Thread(target=checked_back)
    back.start()
    try:
        _guard(fab, roles, said, gap=0.05).on_freeze(fab.config.lease_ms / 1000.0 + 0.01)
    finally:
        done.set()
        back.join(timeout=10)
    assert roles.told == [("sim-b", 1)], (said, dict(fab.counters))
    assert fab.counters["stale_authority"] >= 1  # its first answer was refused, then asked again


class Hearing:
    """Whether this sim hears, as the deaf stop reads it: cut or not, never frozen."""

    def __init__(self) -> None:
        self.why, self.beat, self.own_gone_at = "", hr.Heartbeat(), float("-inf")

    def cut(self) -> str:
        return self.why

    def frozen(self) -> bool:
        return False


class Commands:
    """A serving peer's command pipeline as the deaf stop holds and resumes it."""

    def __init__(self) -> None:
        self.held = ""

    def hold(self, reason: str) -> None:
        self.held = reason

    def resume(self) -> None:
        self.held = ""


class Peer:
    def __init__(self) -> None:
        self.commands = Commands()


def test_a_cut_off_primary_holds_its_robots_and_lets_them_go_when_it_hears_again(connect):
    fab = connect("sim", "sim-a")
    hearing, peer, said = Hearing(), Peer(), []
    serving: list[Peer | None] = [None]
    stop = DeafStop(
        fab,
        hearing=hearing,
        serving=lambda: serving[0],
        stopping=threading.Event(),
        announce=said.append,
        clock=lambda: 100.0,
    )
    hearing.why = "its link is down"
    stop.look()
    assert said == [] and stop.state.holds == 0  # serving nothing (a standby): nothing to hold
    serving[0] = peer
    stop.look()
    assert peer.commands.held == REASON and stop.state.holds == 1
    assert said[-1].startswith("sim sim-a: hears no one (its link is down); its robots stop")
    stop.look()
    assert stop.state.holds == 1  # held already
    hearing.why = ""
    stop.look()
    assert peer.commands.held == "" and said[-1].startswith("sim sim-a: hears again")
