"""The twist keeper (user_peer.deadman): repeats a held twist until dropped, replaced, refused or closed."""

from __future__ import annotations

import threading

import pytest

from robofabric.testing import wait_until
from user_peer.deadman import TwistKeeper
from user_peer.errors import NotOwner


def test_a_held_twist_is_repeated_until_dropped_and_a_refused_one_ends_its_hold():
    keeper = TwistKeeper(interval=0.01)
    sent: list[str] = []
    lock = threading.Lock()

    def sender(name: str):
        def send() -> None:
            with lock:
                sent.append(name)

        return send

    try:
        keeper.hold("base1", sender("a"))
        wait_until(lambda: sent.count("a") >= 3, what="three repeats")
        keeper.hold("base1", sender("b"))  # the next twist replaces it
        wait_until(lambda: sent.count("b") >= 3, what="the new twist repeated")
        with lock:
            n_a = sent.count("a")
        keeper.drop("base1")
        assert not keeper.holding("base1")
        with lock:
            n = len(sent)
        keeper.hold("base2", sender("c"))  # another robot's repeats go on: base1's stopped
        wait_until(lambda: sent.count("c") >= 3, what="base2 repeated")
        with lock:
            assert sent.count("a") == n_a and [s for s in sent[n:] if s != "c"] == []  # none after the drop returned

        def lost() -> None:
            raise NotOwner("base3 changed hands since the command was given (epoch 4, now 5)")

        keeper.hold("base3", lost)
        wait_until(lambda: not keeper.holding("base3"), what="the refused twist's hold ended")
        assert "changed hands" in keeper.ended["base3"] and keeper.holding("base2")
    finally:
        keeper.close()
    assert not keeper.holding("base2")
    keeper.hold("base4", sender("d"))  # closed: nothing is held any more
    assert not keeper.holding("base4")


def test_the_interval_must_be_positive():
    with pytest.raises(ValueError, match="positive"):
        TwistKeeper(interval=0)


def test_a_drop_returns_only_after_a_resend_under_way_went_so_none_lands_after_the_next_command():
    """The full suite saw a stop's zero twist followed by the old twist's resend, read before the drop: the base
    drove on until the sim's deadman. A drop now waits for the resend under way, and nothing of the old hold
    goes out after it."""
    keeper = TwistKeeper(interval=0.01)
    order: list[str] = []
    entered, release, dropped = threading.Event(), threading.Event(), threading.Event()

    def slow_send() -> None:
        entered.set()
        release.wait(10)
        order.append("resent")

    try:
        keeper.hold("base1", slow_send)
        assert entered.wait(10), "no resend began"

        def drop() -> None:
            keeper.drop("base1")
            order.append("dropped")
            dropped.set()

        threading.Thread(target=drop, daemon=True).start()
        assert not dropped.wait(0.3), "the drop returned while the old twist's resend was still under way"
        release.set()
        assert dropped.wait(10)
        assert order == ["resent", "dropped"] and not keeper.holding("base1")
    finally:
        release.set()
        keeper.close()
