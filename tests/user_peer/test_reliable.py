"""resend_until: a stop is sent again until the robot shows it, with a fake clock."""

from __future__ import annotations

from fabric.rate import FakeClock
from user_peer.reliable import resend_until


def test_sends_again_until_done():
    clock = FakeClock()
    sent = []

    def send():
        sent.append(clock.now())

    r = resend_until(send, lambda: len(sent) >= 3, interval=0.1, timeout=5.0, poll=0.01, clock=clock, sleep=clock.sleep)
    assert r.done and r.sends == 3 and len(sent) == 3
    assert [round(t, 2) for t in sent] == [0.0, 0.1, 0.2]


def test_done_at_once_sends_once():
    clock = FakeClock()
    r = resend_until(lambda: None, lambda: True, clock=clock, sleep=clock.sleep)
    assert r.done and r.sends == 1 and r.seconds == 0.0


def test_gives_up_after_the_timeout():
    clock = FakeClock()
    r = resend_until(lambda: None, lambda: False, interval=0.25, timeout=1.0, poll=0.05, clock=clock, sleep=clock.sleep)
    assert not r.done and r.sends == 4 and 1.0 <= r.seconds < 1.1
