"""A sim's hold is shown as a pause, not an error: the console's event line and its refusal words, and the test the
ROS 2 bridge uses to tell a pause from a refusal (user_peer.pause)."""

from __future__ import annotations

from fabric.interfaces import Event
from user_peer.console.page import event_line
from user_peer.pause import is_pause, pause_words
from user_peer.robot import HELD, OWNERSHIP_REFUSAL, RESUMED


def _reject(code: str) -> Event:
    return Event(kind="reject", reason=code, object="arm1", user="alice", data={"command": "joints", "code": code})


def test_a_held_refusal_is_a_pause_and_other_refusals_are_not():
    assert is_pause(_reject(HELD))
    assert not is_pause(_reject(OWNERSHIP_REFUSAL))
    assert not is_pause(_reject("wrong_body"))
    assert not is_pause(Event(kind="owner_stop", reason="held", object="arm1", data={"code": HELD}))


def test_the_console_says_the_sim_is_paused_not_reject():
    line = event_line(_reject(HELD), True)
    assert line.startswith("trusted · the sim is paused: arm1") and "[alice]" in line
    assert "reject" not in line
    assert event_line(_reject("wrong_body"), True) == "trusted · reject arm1 [alice]: wrong_body"
    assert pause_words("arm1") in event_line(_reject(HELD), False) and event_line(_reject(HELD), False).startswith(
        "unverified"
    )


def test_the_sims_word_once_it_hears_again_reads_as_the_end_of_the_pause():
    back = Event(
        kind="reject",
        reason="held",
        object="arm1",
        user="alice",
        data={
            "command": "?",
            "code": RESUMED,
            "detail": "the sim held its robots and stopped this one before its "
            "command was done; it hears again: send the command again",
        },
    )
    assert is_pause(back)
    assert event_line(back, True).startswith("trusted · the sim was paused and hears again: arm1 stopped")
