"""Bumper stops in words for /rosout (user_peer.ros2.bumps): one line per robot stopped since the last report, a
warning for a base the bridge drives and info for the others, with the sim's time and how many stops."""

from __future__ import annotations

from fabric.interfaces import Event, EventKind
from user_peer.ros2.bumps import bump_lines


def bump(rid: str, t: float) -> Event:
    return Event(
        kind=EventKind.COLLISION,
        object=rid,
        reason="bumper",
        severity="warning",
        data={"t": t, "detail": "stopped before an obstacle ahead"},
    )


def test_each_stopped_base_is_one_line_a_warning_when_the_bridge_drives_it():
    events = [bump("base2", 3.0), Event(kind=EventKind.CLAMP, object="base1"), bump("base1", 4.5), bump("base1", 4.75)]
    assert bump_lines(events, {"base1"}) == [
        (
            True,
            "bumper stop: base1 at sim time 4.75 s, stopped before an obstacle ahead (2 stops since the last report)",
        ),
        (False, "bumper stop: base2 at sim time 3.00 s, stopped before an obstacle ahead"),
    ]


def test_an_event_without_data_still_says_its_reason_and_none_says_nothing():
    assert bump_lines([Event(kind=EventKind.COLLISION, object="base1", reason="bumper")], ()) == [
        (False, "bumper stop: base1, bumper")
    ]
    assert bump_lines([], {"base1"}) == []
