"""A peer's close never blocks for ever: zenoh's own close once did not return (a whole suite beside a CPU hog)."""

import threading
import time

from fabric.session import close_within


def test_a_close_that_does_not_return_is_left_after_its_limit_and_said(caplog):
    release = threading.Event()
    t0 = time.monotonic()
    try:
        assert close_within(lambda: release.wait(30.0), 0.3, "the stuck session") is False
        assert 0.3 <= time.monotonic() - t0 < 5.0
        assert "the stuck session did not close within 0.3 s" in caplog.text
    finally:
        release.set()


def test_a_close_that_returns_or_raises_is_done():
    assert close_within(lambda: None, 5.0, "a session") is True
    assert close_within(lambda: 1 / 0, 5.0, "a broken session") is True  # its error is the closing session's own


def test_a_real_session_closes_within_its_limit(connect):
    fab = connect("tool", "closer")
    fab.close()
    assert fab.closed and fab.counters["closes_hung"] == 0
