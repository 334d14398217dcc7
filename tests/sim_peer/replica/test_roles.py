"""The election's shell built on its own: a real fabric, a recording shard, the serving lock, the stop flag, the
effects' callbacks and a clock passed in (a fake one but where the heartbeat must run), no ReplicaHost.

A standby takes the world over on a thread of its own once its leader's token went; a primary that
hears a higher term muzzles itself and steps down; a sim's token coming and going is kept with its time and asks
the shard directory; a new term is shown."""

from __future__ import annotations

import threading
import time
from typing import Callable

import pytest

from robofabric.testing import wait_until
from sim_peer.replica import election as el
from sim_peer.replica.roles import Roles


class Shard:
    """The shard directory's side of the seam: every live sim is of this shard; what it was asked is recorded."""

    def __init__(self) -> None:
        self.asked: list[str] = []

    def learn(self) -> None:
        self.asked.append("learn")

    def learn_soon(self) -> None:
        self.asked.append("learn_soon")

    def view(self, live: frozenset[str]) -> frozenset[str]:
        return live


class Effects:
    """What the roles make the host do, recorded, and the clock they read."""

    def __init__(self, clock: Callable[[], float] | None = None) -> None:
        self.now = 50.0
        self.clock = clock or (lambda: self.now)
        self.said: list[str] = []
        self.taken: list[tuple[float, str | None]] = []
        self.reasserted: list[int] = []
        self.shown: list[el.Election] = []
        self.adopting = 0
        self.shard, self.lock, self.stopping = Shard(), threading.RLock(), threading.Event()

    def roles(self, fab, election: el.Election) -> Roles:
        return Roles(
            fab,
            election,
            shard=self.shard,
            serving_lock=self.lock,
            stopping=self.stopping,
            announce=self.said.append,
            take_over=lambda t0, former: self.taken.append((t0, former)),
            reassert=self.reasserted.append,
            show_role=self.shown.append,
            adopt_soon=self.adopt,
            clock=self.clock,
        )

    def adopt(self) -> None:
        self.adopting += 1


@pytest.mark.slow  # the leader's token goes, and it falls silent for a second (AUDIBLE_S) before the take-over
def test_a_standby_takes_the_world_over_on_its_own_thread_once_its_leaders_token_went(connect):
    leader, fab = connect("sim", "sim-a"), connect("sim", "sim-b")
    effects = Effects(clock=time.monotonic)  # the heartbeat's and the wait's real time
    roles = effects.roles(fab, el.Election("sim-b", el.STANDBY, 1, "sim-a"))
    try:
        roles.join()
        assert roles.live_sims() == frozenset({"sim-a", "sim-b"}) and roles.settled and effects.taken == []
        assert "learn_soon" in effects.shard.asked  # a sim's token came: which shard is it?
        t0 = time.monotonic()
        leader.close()  # its token goes
        wait_until(lambda: effects.taken, timeout=30, what="the take-over", seen=lambda: effects.said)
        ((at, former),) = effects.taken
        assert former == "sim-a" and at >= t0  # on the clock it was given, draining the leader it followed
        assert (roles.election.role, roles.election.term) == (el.PRIMARY, 2)
        assert any("the token of sim-a is gone" in s and "taking over with term 2" in s for s in effects.said)
        roles.taking_over.join(10.0)
    finally:
        effects.stopping.set()


def test_a_primary_that_hears_a_higher_term_muzzles_itself_and_steps_down(connect):
    fab = connect("sim", "sim-a")
    effects = Effects()
    roles = effects.roles(fab, el.start("sim-a", standby=False, term=1))
    roles.heard("sim-x", 1)  # the same term from a higher id: this one stays
    assert roles.role == el.PRIMARY and not roles.stepped_down.is_set()
    roles.heard("sim-x", 5)
    assert roles.stepped_down.is_set() and fab.stamp.muzzled
    assert (roles.election.role, roles.election.term, roles.election.leader) == (el.STANDBY, 5, "sim-x")
    assert effects.said == ["sim sim-a: sim-x holds term 5; stepping down to standby"]
    assert effects.shown[-1] == roles.election and roles.heard_at["sim-x"] == 50.0
    assert effects.taken == [] and effects.reasserted == []


def test_a_resumed_primary_asserts_its_term_again_and_a_new_term_is_shown(connect):
    fab = connect("sim", "sim-a")
    effects = Effects()
    roles = effects.roles(fab, el.start("sim-a", standby=False, term=3))
    roles.step(el.Resumed())
    assert effects.reasserted == [4] and roles.election.term == 4  # one term up: whoever fenced at a rival's takes it
    with effects.lock:  # as a rebuild calls it, under the serving lock
        roles.set_term(6)
    assert roles.election.term == 6 and effects.shown[-1].term == 6


def test_tokens_coming_and_going_are_kept_with_their_time_and_ask_the_shard(connect):
    fab = connect("sim", "sim-a")
    effects = Effects()
    roles = effects.roles(fab, el.start("sim-a", standby=False, term=1))
    roles.on_sim("sim", "sim-c", True)
    assert roles.live_sims() == frozenset({"sim-c"}) and effects.shard.asked == ["learn_soon"]
    effects.now = 60.0
    roles.on_sim("sim", "sim-c", False)  # before the first view is settled: kept, decides nothing
    assert roles.live_sims() == frozenset() and roles.gone_at == {"sim-c": 60.0}
    assert roles.gone_since(59.0) == {"sim-c"} and roles.gone_since(61.0) == set()
    assert effects.taken == [] and roles.role == el.PRIMARY


def test_a_fresh_standby_that_hears_its_leader_before_its_token_does_not_take_the_world_over(connect):
    """A restarted standby's session can hear its leader's streams before the leader's token reaches it (a fresh
    session's first liveliness view may lack live sims), and the shard directory's view taken before then arrives
    after it followed the leader. That view is no news of the leader's death: the leader is heard, its token never
    seen. The soak saw a restarted sim-b take the world over from no state there while sim-a served on. Once the
    token came and went, its loss is trusted at once, heard or not: a killed leader's fail-over waits for nothing."""
    fab = connect("sim", "sim-b")
    effects = Effects()
    roles = effects.roles(fab, el.start("sim-b", standby=True))  # a fresh process: no leader, no step-down
    try:
        roles.join()  # the leader's token is nowhere yet: the first view is this sim alone
        assert roles.live_sims() == frozenset({"sim-b"}) and roles.settled
        roles.heard("sim-a", 3)  # its term on a stream, before its token
        assert "standby sim-b: following sim-a (term 3)" in effects.said
        roles.shards_learnt(frozenset({"sim-b"}))  # the shard directory's view, taken before the token came
        assert effects.taken == [] and roles.role == el.STANDBY, effects.said
        assert any("the token of sim-a is missing, but it is still heard" in s for s in effects.said)

        leader = connect("sim", "sim-a")  # its token reaches this session
        wait_until(lambda: "sim-a" in roles.live_sims(), timeout=10, what="the leader's token")
        wait_until(lambda: roles.election.leader_seen and not roles.relooking, timeout=10, what="the relook ended")
        assert effects.taken == [] and roles.role == el.STANDBY

        effects.now += 0.1  # heard a moment ago, but its token was seen and went: no alibi
        leader.close()
        # its token's going reaches this session a moment later (at load, after the next line once: nothing taken)
        wait_until(lambda: "sim-a" not in roles.live_sims(), timeout=10, what="the leader's token gone")
        roles.shards_learnt(frozenset({"sim-b"}))
        wait_until(lambda: effects.taken, timeout=10, what="the take-over", seen=lambda: effects.said[-3:])
        assert [former for _, former in effects.taken] == ["sim-a"] and roles.election.term == 4
        roles.taking_over.join(10.0)
    finally:
        effects.stopping.set()
