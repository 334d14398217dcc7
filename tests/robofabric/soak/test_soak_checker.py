"""The checker on hand-made histories: each invariant finds its violation, stays quiet on a clean history,
and prints the excerpt that shows it; a generated clean history has no violation, and any of a set of
corruptions of it is caught by the invariant it breaks."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from robofabric.soak.checker import INVARIANTS, Limits, blind, check, memory_judged, not_judged, summary
from robofabric.soak.history import Cmd, Fault, Joints, Mark, OwnEvent, OwnRec, ProcExit, ProcSample

A = (0.6, 0.3, -0.3, 0.0, 0.5, 0.1)
B = (0.4, 0.1, -0.1, 0.2, 0.2, -0.2)
POISON = (-0.6, 0.0, 0.0, 0.0, -0.3, 0.0)


def rec(t, owner, epoch, *, queue=(), state="still", source="sim-a", term=1, obj="arm0"):
    return OwnRec(t, obj, owner, epoch, tuple(queue), state, source, term)


def js(t, q, *, source="sim-a", term=1, robot="arm0"):
    return Joints(t, robot, tuple(q), t, source, term)


def only(inv, history, lim=Limits()):
    return INVARIANTS[inv](sorted(history, key=lambda r: r.t), lim)


# ---------------------------------------------------------------------- owners


def test_two_owners_at_one_epoch_is_a_violation_with_both_records():
    h = [rec(1, "ann", 3), rec(2, "bob", 3)]
    (v,) = only("owners", h)
    assert "two owners at epoch 3: ann and bob" in v.message and v.excerpt == tuple(h)


def test_an_epoch_going_back_is_a_violation_but_a_fenced_stale_record_is_not():
    assert [v.message for v in only("owners", [rec(1, "ann", 5), rec(2, "", 4, term=1)])] == [
        "arm0's epoch went back from 5 to 4"
    ]
    stale = [
        rec(1, "ann", 5, term=2, source="sim-b"),
        rec(2, "bob", 4, term=1),
    ]  # a paused old primary: consumers drop it
    assert only("owners", stale) == []


def test_owners_clean():
    assert only("owners", [rec(1, "ann", 1), rec(2, "", 2), rec(3, "bob", 3), rec(4, "bob", 3, state="moving")]) == []


# ---------------------------------------------------------------------- applied


def test_a_robot_reaching_a_target_only_a_stale_command_asked_for_is_a_violation():
    c = Cmd(3.0, "arm0", "ann", 1, "joints", POISON)
    h = [rec(1, "ann", 2), Cmd(1.5, "arm0", "ann", 2, "joints", A), js(2, A), c, js(4, POISON)]
    (v,) = only("applied", h)
    assert "ann's command at epoch 1" in v.message and "owner ann epoch 2" in v.message
    assert c in v.excerpt and js(4, POISON) in v.excerpt


def test_a_refused_command_whose_target_is_never_reached_is_fine():
    h = [
        rec(1, "ann", 2),
        Cmd(1.5, "arm0", "ann", 2, "joints", A),
        js(2, A),
        Cmd(3.0, "arm0", "ann", 1, "joints", POISON),
        js(4, A),
    ]
    assert only("applied", h) == []


def test_a_late_command_with_an_owners_target_proves_nothing():
    h = [rec(1, "ann", 2), Cmd(1.5, "arm0", "ann", 2, "joints", A), Cmd(3.0, "arm0", "bob", 7, "joints", A), js(4, A)]
    assert only("applied", h) == []


# ---------------------------------------------------------------------- reset


def test_joints_jumping_across_a_fail_over_is_a_violation():
    h = [js(1, A), js(3, (0.0,) * 6, source="sim-b", term=2)]
    (v,) = only("reset", h)
    assert "across the change from sim-a to sim-b" in v.message and v.excerpt == tuple(h)


def test_joints_jumping_within_one_sim_faster_than_it_can_move_is_a_violation():
    (v,) = only("reset", [js(1.0, A), js(1.1, (0.0,) * 6)])
    assert "between two samples of one sim" in v.message


def test_samples_the_observer_took_in_a_burst_are_judged_on_the_sims_time():
    a, b = Joints(1.0, "arm0", A, 10.0, "sim-a", 1), Joints(1.05, "arm0", B, 10.3, "sim-a", 1)
    assert only("reset", [a, b]) == []


def test_a_fail_over_the_observer_was_blind_to_allows_the_motion_it_missed_and_no_more():
    """A router restart hides the old sim's last samples and the new one's first: the robot may have moved at speed
    for the blind stretch (here 1.5 s: 3 rad/s allows 4.5 rad), and not for the time the observer could see."""
    far = tuple(x + 1.0 for x in A)
    assert only("reset", [js(1.0, A), Fault(2, "router", "router", 3), js(3.0, far, source="sim-b", term=2)]) == []
    (v,) = only(
        "reset",
        [js(1.0, A), Fault(9, "router", "router", 10), js(10.5, A), js(12, A), js(12.5, far, source="sim-b", term=2)],
    )
    assert "across the change from sim-a to sim-b" in v.message


def test_joints_moving_at_speed_and_a_smooth_fail_over_are_fine():
    h = [js(1.0, A), js(2.0, B), js(4.0, tuple(x + 0.05 for x in B), source="sim-b", term=2)]
    assert only("reset", h) == []


# ---------------------------------------------------------------------- handover


def test_an_owner_losing_a_moving_robot_without_a_reason_is_a_violation():
    h = [rec(1, "ann", 1, state="moving"), rec(2, "bob", 2, state="moving")]
    (v,) = only("handover", h)
    assert "left ann for bob while moving" in v.message


def test_an_owner_change_while_the_observer_was_blind_is_counted_not_judged_when_records_were_missed():
    """A router restart blinds the observer until it hears the wire again (and a margin): an owner change across that
    stretch whose records were missed there (an epoch gap) is not judged (the event that explains it may be lost),
    but counted; one whose records all came (the observer caught up: consecutive epochs) is judged, as is the same
    change in sight."""
    moving, taken = rec(1, "ann", 1, state="moving"), rec(4, "bob", 3)
    blind_h = [moving, Fault(2, "router", "router", 3), js(3.2, A), taken]
    assert only("handover", blind_h) == [] and only("queue", blind_h) == []
    assert blind(blind_h) == [(2, 3.7)] and not_judged(blind_h) == 1
    assert summary(blind_h, [])[0] == (
        "observer blind: 1 router restarts, 1.7 s in all; not judged: 1 (owner changes "
        "whose records the observer missed there and did not catch up on)"
    )
    caught_up = [moving, Fault(2, "router", "router", 3), js(3.2, A), rec(4, "bob", 2)]
    assert [v.invariant for v in check(caught_up)] == ["handover"] and not_judged(caught_up) == 0
    assert summary(caught_up, [])[0] == "observer blind: 1 router restarts, 1.7 s in all; not judged: 0"
    # both records after the observer heard the wire again: in sight, judged
    late = [Fault(2, "router", "router", 3), js(3.2, A), rec(5, "ann", 1, state="moving"), rec(6, "bob", 2)]
    assert [v.invariant for v in check(late)] == ["handover"] and not_judged(late) == 0


def test_release_expiry_and_take_over_of_a_still_robot_are_fine():
    h = [
        rec(1, "ann", 1, state="moving"),
        OwnEvent(2, "own_released", "arm0", "ann", "released", "sim-a"),
        rec(2, "", 2),
        rec(3, "bob", 3, state="moving"),
        OwnEvent(4, "own_expired", "arm0", "bob", "lease expired", "sim-a"),
        rec(4, "cat", 4, state="still"),
        rec(5, "dan", 5),
    ]
    assert only("handover", h) == []


# ---------------------------------------------------------------------- queue


def test_a_queue_changing_order_or_skipping_a_waiting_user_is_a_violation():
    (v,) = only(
        "queue", [rec(1, "ann", 1, queue=("bob", "cat"), state="moving"), rec(2, "ann", 1, queue=("cat", "bob"))]
    )
    assert "changed order" in v.message
    released = OwnEvent(2, "own_handover", "arm0", "cat", "released by ann", "sim-a")
    (w,) = only("queue", [rec(1, "ann", 1, queue=("bob", "cat")), released, rec(2, "cat", 2, queue=("bob",))])
    assert "went to cat ahead of bob" in w.message


def test_a_still_robot_taken_over_by_a_queued_user_skips_nobody():
    """A take-over of a still robot goes to whoever asked (the authority's rule), queued behind others or not."""
    assert only("queue", [rec(1, "ann", 1, queue=("bob", "cat")), rec(2, "cat", 2, queue=("bob",))]) == []


def test_a_queue_handing_over_in_order_is_fine():
    assert (
        only("queue", [rec(1, "ann", 1, queue=("bob", "cat")), rec(2, "bob", 2, queue=("cat",)), rec(3, "cat", 3)])
        == []
    )


# ---------------------------------------------------------------------- unowned motion


def test_a_robot_moving_long_after_its_owner_went_is_a_violation():
    (v,) = only("unowned_motion", [rec(1, "", 2), js(5, A), js(5.2, tuple(x - 0.1 for x in A))])
    assert "with no owner" in v.message


def test_a_robot_stopping_after_its_owner_went_is_fine():
    assert only("unowned_motion", [rec(1, "", 2), js(1.5, B), js(2.5, A), js(5, A), js(7, A)]) == []


def test_a_robot_moving_between_two_samples_that_span_a_new_grant_is_owned():
    """Joints are thinned while still: the step from the last still sample to the first moving one may span the grant."""
    assert only("unowned_motion", [rec(1, "", 2), js(2, A), js(8, A), rec(8.5, "ann", 3), js(8.7, B)]) == []


def test_a_grant_heard_after_the_joints_it_moved_is_owned_when_her_command_at_that_epoch_came_first():
    """The observer hears records, commands and joints by different routes: the soak heard s02's command at epoch 18,
    the moving joints, then the record of her grant at 18. The command proves the grant came first; without it (or
    with the record too late, or naming someone else) the motion is unowned."""
    moved = tuple(x - 0.06 for x in B)
    base = [rec(1, "", 17), js(5, B), js(6.0, moved)]
    cmd = Cmd(5.99, "arm0", "s02", 18, "joints", A)
    assert only("unowned_motion", [*base, cmd, rec(6.001, "s02", 18)]) == []
    assert len(only("unowned_motion", [*base, rec(6.001, "s02", 18)])) == 1  # no command of hers: unowned
    assert len(only("unowned_motion", [*base, cmd, rec(7.0, "s02", 18)])) == 1  # the record long after
    assert len(only("unowned_motion", [*base, cmd, rec(6.001, "bob", 18)])) == 1  # another owner
    assert len(only("unowned_motion", [*base, Cmd(5.99, "arm0", "s02", 17, "joints", A), rec(6.001, "s02", 18)])) == 1


def test_a_grant_whose_command_too_was_heard_after_the_joints_it_moved_is_owned():
    """The two-minute soak at load 13: s01's arm moved (joints at 91.899), then her command at epoch 10 (91.905) and
    the record of her grant (91.905) came, each by its own route. A command heard long after proves nothing."""
    moved = tuple(x + 0.06 for x in B)
    base = [rec(85.079, "", 9), js(91.086, B), js(91.899, moved)]
    late = [Cmd(91.905, "arm0", "s01", 10, "joints", A), rec(91.905, "s01", 10)]
    assert only("unowned_motion", [*base, *late]) == []
    much_later = [Cmd(92.5, "arm0", "s01", 10, "joints", A), rec(91.905, "s01", 10)]
    assert len(only("unowned_motion", [*base, *much_later])) == 1


# ---------------------------------------------------------------------- resources and exits


def _samples(name, slope_mb_h, *, minutes=20, threads=20, fd_rise=0, log_rise=0):
    return [
        ProcSample(
            60.0 * m,
            name,
            7,
            100 + slope_mb_h * m / 60,
            threads,
            30 + (fd_rise if m > minutes / 2 else 0),
            1000 + log_rise * m,
        )
        for m in range(minutes + 1)
    ]


def test_memory_fds_and_logs_growing_after_warm_up_are_violations():
    h = [Mark(0, "warm"), *_samples("sim-a", 60, fd_rise=40, log_rise=10_000_000)]
    msgs = [v.message for v in only("resources", h)]
    assert any("memory grew 60.0 MB/h" in m for m in msgs)
    assert any("fds rose from 30 to 70" in m for m in msgs)
    assert any("log grew" in m for m in msgs)


def test_a_restarted_peer_warms_up_as_long_as_the_run_did():
    first = [ProcSample(60.0 * m, "sim-a", 7, 100.0, 20, 30, 0) for m in range(40)]
    again = [
        ProcSample(60.0 * m, "sim-a", 8, 60 + (m - 40) * 6.0 if m < 45 else 90.0, 20, 30, 0) for m in range(40, 70)
    ]
    h = [
        Mark(0, "class"),
        Mark(300, "warm"),
        *first,
        *again,
    ]  # the restart grows 30 MB in its first 5 minutes, then flat
    assert only("resources", h) == []  # judged from its 5th minute: flat (from its 2nd, 23 MB/h)


def test_flat_resources_and_short_windows_are_fine():
    assert only("resources", [Mark(0, "warm"), *_samples("sim-a", 5)]) == []
    assert only("resources", [Mark(0, "warm"), *_samples("sim-a", 500, minutes=5)]) == []  # too short to judge


def test_an_exit_nobody_caused_is_a_violation_and_an_expected_one_is_not():
    h = [ProcExit(1, "compute", 9, 1, False, "Traceback..."), ProcExit(2, "sim-a", 8, -9, True)]
    (v,) = only("exits", h)
    assert "compute (pid 9) ended with 1" in v.message


def test_summary_counts_faults_by_kind_and_violations():
    h = [Fault(1, "pause", "sim-a", 2), Fault(3, "pause", "s00", 4), Fault(5, "router", "router", 6)]
    lines = summary(h, check([rec(1, "ann", 3), rec(2, "bob", 3)]))
    assert lines[1:] == [
        "memory: no samples",
        "faults: 3",
        "fault kinds: 2 (pause 2, router 1)",
        "violations: 1 (owners 1)",
    ]


def test_the_summary_names_whose_memory_was_judged_and_whose_was_not():
    """A peer alive all run (the compute peer with ``--victims sim,student``) is judged; one killed too often is
    named as not judged."""
    short = [ProcSample(60.0 * m + 1, "compute", 10 + m, 80.0, 10, 20, 0) for m in range(20)]  # a new pid each minute
    h = [Mark(0, "warm"), *_samples("sim-a", 1.5), *short]
    assert memory_judged(h) == [
        "compute not judged (no incarnation lived past its warm-up long enough)",
        "sim-a +1.5 MB/h over 19 min",
    ]  # its first minute is its warm-up
    assert (
        summary(h, [])[1]
        == "memory: compute not judged (no incarnation lived past its warm-up long enough); sim-a +1.5 MB/h over 19 min"
    )
    assert (
        str(check([rec(1, "ann", 3), rec(2, "bob", 3)])[0])
        .splitlines()[1]
        .strip()
        .startswith("t=1.000 record arm0: owner=ann")
    )


# ---------------------------------------------------------------------- a generated class


@st.composite
def histories(draw):
    """A clean history of one arm: requests, releases, take-overs of a still arm, queue handovers, fail-overs
    (a new term, the joints carried on), the arm moving between owners' targets at a possible speed."""
    users = ["ann", "bob", "cat"]
    t, epoch, owner, queue, term, q = 0.0, 0, "", [], 1, list(A)
    out: list = [rec(t, owner, epoch)]
    for step in draw(
        st.lists(st.sampled_from(["take", "release", "queue", "move", "failover"]), min_size=1, max_size=25)
    ):
        t += draw(st.floats(0.5, 3.0))
        src = f"sim-{term}"
        if step == "take" and (not owner or True):
            new = draw(st.sampled_from(users))
            if new != owner:
                epoch += 1
                owner = new
                queue = [u for u in queue if u != new]
                out.append(rec(t, owner, epoch, queue=queue, source=src, term=term))
        elif step == "release" and owner:
            out.append(
                OwnEvent(
                    t,
                    "own_released" if not queue else "own_handover",
                    "arm0",
                    owner if not queue else queue[0],
                    "released" if not queue else f"released by {owner}",
                    src,
                )
            )
            epoch += 1
            owner = queue.pop(0) if queue else ""
            out.append(rec(t, owner, epoch, queue=queue, source=src, term=term))
        elif step == "queue" and owner:
            u = draw(st.sampled_from(users))
            if u != owner and u not in queue:
                queue.append(u)
                out.append(rec(t, owner, epoch, queue=queue, source=src, term=term))
        elif step == "move" and owner:
            target = draw(st.sampled_from([A, B]))
            out.append(Cmd(t, "arm0", owner, epoch, "joints", target))
            out.append(js(t + 0.01, q, source=src, term=term))
            q = list(target)
            out.append(js(t + 0.5, q, source=src, term=term))
        elif step == "failover":
            term += 1
            out.append(rec(t, owner, epoch, queue=queue, source=f"sim-{term}", term=term))
            out.append(js(t, q, source=f"sim-{term}", term=term))
    return sorted(out, key=lambda r: r.t)


@settings(max_examples=60, deadline=None)
@given(histories())
def test_a_generated_clean_history_has_no_violation(h):
    assert check(h) == []


@settings(max_examples=60, deadline=None)
@given(histories(), st.sampled_from(["owners", "reset", "applied"]))
def test_a_corrupted_history_is_caught_by_the_invariant_it_breaks(h, how):
    last = h[-1].t
    if how == "owners":
        top = max(r.epoch for r in h if isinstance(r, OwnRec))
        bad = [rec(last + 1, "zed", top + 1, term=99, source="x"), rec(last + 2, "yan", top + 1, term=99, source="x")]
    elif how == "reset":
        bad = [js(last + 1, A, term=99, source="x"), js(last + 2, (0.0,) * 6, term=100, source="y")]
    else:
        bad = [
            rec(last + 1, "zed", 1000, term=99, source="x"),
            js(last + 1.5, A, term=99, source="x"),
            Cmd(last + 2, "arm0", "zed", 999, "joints", POISON),
            js(last + 3, POISON, term=99, source="x"),
        ]
    assert how in {v.invariant for v in check(sorted(h + bad, key=lambda r: r.t))}
