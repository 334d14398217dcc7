"""The pure core of the deaf stop (sim_peer.replica.deaf_rule): a primary cut off holds its robots and resumes once it hears
again; one only late holds them only if its router does not answer, and says once that it was late. Unit tests
with the time passed in, then a property test over random looks, with the robots' hold driven by the effects as
the shell drives it."""

from __future__ import annotations

import math

from hypothesis import given, settings, strategies as hs

from sim_peer.replica import deaf_rule as dr
from sim_peer.replica import hearing_rule as hr

LEASE = 2.0
CUT = "its link is down"


def look(
    now: float,
    *,
    held: bool = False,
    cut: str = "",
    frozen: bool = False,
    beat: hr.Heartbeat | None = None,
    own_gone_at: float = -math.inf,
    answered_at: float | None = None,
) -> dr.Look:
    return dr.Look(
        now=now,
        held=held,
        cut=cut,
        frozen=frozen,
        beat=beat or hr.Heartbeat(last_tick=now),
        own_gone_at=own_gone_at,
        lease=LEASE,
        answered_at=answered_at,
    )


def test_a_primary_cut_off_holds_its_robots_once_and_resumes_when_it_hears_again():
    s, eff = dr.step(dr.DeafState(), look(1.0, cut=CUT))
    assert eff == [dr.Hold(CUT)] and s.holds == 1
    assert not dr.must_ask(s, look(1.0, cut=CUT, frozen=True))  # a cut needs no router to tell
    s, eff = dr.step(s, look(1.05, cut=CUT, held=True))
    assert eff == [] and s.holds == 1
    s, eff = dr.step(s, look(1.1, held=True))
    assert eff == [dr.Resume()] and s.holds == 1


def test_a_primary_only_late_asks_its_router_and_serves_on_when_it_answers_telling_it_once():
    thawed = hr.Heartbeat(last_tick=5.0, thawed_at=5.0, late_s=1.5)
    s = dr.DeafState()
    seen = look(5.05, frozen=True, beat=thawed)
    assert dr.must_ask(s, seen)
    s, eff = dr.step(s, look(5.05, frozen=True, beat=thawed, answered_at=5.06))
    assert eff == [dr.WasLate(1.5)] and (s.holds, s.lates, s.proven_at) == (0, 1, 5.06)
    s, eff = dr.step(s, look(5.1, frozen=True, beat=thawed))  # proven for this freeze: no new question
    assert eff == [] and not dr.must_ask(s, look(5.1, frozen=True, beat=thawed))
    again = hr.Heartbeat(last_tick=9.0, thawed_at=9.0, late_s=2.0)  # a new freeze needs a new proof
    assert dr.must_ask(s, look(9.0, frozen=True, beat=again))
    assert dr.must_ask(s, look(5.2, frozen=True, beat=thawed, own_gone_at=5.1))  # so does our token going


def test_a_late_primary_whose_router_does_not_answer_holds_until_it_does():
    thawed = hr.Heartbeat(last_tick=5.0, thawed_at=5.0, late_s=1.5)
    s, eff = dr.step(dr.DeafState(), look(5.05, frozen=True, beat=thawed))
    assert eff == [dr.Hold("frozen or starved 1.5 s, and its router does not answer")]
    s, eff = dr.step(s, look(5.1, held=True, frozen=True, beat=thawed, answered_at=5.2))
    assert eff == [dr.Resume()] and s.told_thaw == 5.0 and s.proven_at == 5.2
    s, eff = dr.step(s, look(5.3, frozen=True, beat=thawed))  # it was held: no 'was late' after the resume
    assert eff == [] and s.lates == 0


def test_while_the_heartbeat_is_late_right_now_a_proof_lasts_half_a_second():
    late = hr.Heartbeat(last_tick=5.0)
    s = dr.DeafState(proven_at=6.0)
    assert not dr.must_ask(s, look(6.0 + dr.PROOF_S - 0.01, frozen=True, beat=late))
    assert dr.must_ask(s, look(6.0 + dr.PROOF_S + 0.01, frozen=True, beat=late))
    on_time = hr.Heartbeat(last_tick=6.6, thawed_at=5.5, late_s=0.5)
    assert not dr.must_ask(s, look(6.6, frozen=True, beat=on_time))


def test_a_primary_that_hears_and_is_not_frozen_does_nothing():
    assert dr.step(dr.DeafState(), look(3.0)) == (dr.DeafState(), [])


looks = hs.lists(
    hs.tuples(
        hs.floats(0.01, 2.0),
        hs.sampled_from(["", CUT, "the router no longer holds its token"]),
        hs.booleans(),
        hs.sampled_from(["tick", "freeze", "unlink", "own"]),
        hs.booleans(),
    ),
    min_size=1,
    max_size=50,
)


@settings(max_examples=200, deadline=None)
@given(looks)
def test_property_the_robots_are_held_exactly_while_the_primary_hears_no_one(steps):
    """Random looks (cut or not, frozen or not, the heartbeat ticking, freezing or finding the link down, the own
    token going, the router answering or not), the hold carried out as the shell does: after each look the robots
    are held if and only if the look's verdict was 'hears no one'; a hold or a resume comes only when it changes
    something; every hold is counted; a freeze is told as late at most once, and never while held."""
    now, held, holds = 0.0, False, 0
    s, beat, own_gone = dr.DeafState(), hr.Heartbeat(last_tick=0.0), -math.inf
    told: list[float] = []
    for dt, cut, frozen, what, answers in steps:
        now += dt
        if what == "freeze":
            beat = hr.tick(beat, now, gap=0.0, connected=True)  # whatever the gap: a freeze ends now
        elif what == "unlink":
            beat = hr.tick(beat, now, gap=LEASE / 2, connected=False)
        elif what == "own":
            own_gone = now
        else:
            beat = hr.tick(beat, now, gap=LEASE / 2, connected=True)
        seen = look(now, held=held, cut=cut, frozen=frozen, beat=beat, own_gone_at=own_gone)
        asked = dr.must_ask(s, seen)
        assert not (asked and cut)
        if asked and answers:
            seen = dr.Look(now, held, cut, frozen, beat, own_gone, LEASE, answered_at=now)
        verdict = dr.why(s, seen)
        before = s
        s, effects = dr.step(s, seen)
        for e in effects:
            if isinstance(e, dr.Hold):
                assert not held and e.why == verdict
                held, holds = True, holds + 1
            elif isinstance(e, dr.Resume):
                assert held
                held = False
            else:
                assert not held and e.late_s == beat.late_s and beat.thawed_at > before.told_thaw
                told.append(beat.thawed_at)
        assert held == bool(verdict)
        assert s.holds == holds and s.lates == len(told) and len(set(told)) == len(told)
        assert s.proven_at >= before.proven_at
