"""srv/state answered apart (sim_peer.serving.state_answers): a sim-wide budget, a bounded lane, payload asks at once."""

from __future__ import annotations

import threading
from collections import Counter

import pytest

from fabric.budget import RATE_LIMITED, Rate
from fabric.interfaces import Event, ServiceError
from fabric.rate import FakeClock
from robofabric.testing import wait_until
from sim_peer.serving.state_answers import WAITING, StateAnswers


def test_state_asks_spend_the_sims_budget_and_wait_on_a_bounded_lane():
    counters, clock = Counter(), FakeClock()
    answers = StateAnswers(counters, clock=clock.now, budget=Rate(100.0, WAITING + 3))
    gate = threading.Event()
    try:
        assert answers.route("rf/w/srv/state", Event(kind="shard?")) is None  # no capture: answered at once
        submit = answers.route("rf/w/srv/state", None)
        assert submit(gate.wait)  # holds the lane's worker
        wait_until(lambda: answers.lane.waiting() == 0, what="the worker to take it")
        assert all(answers.route("rf/w/srv/state", None)(lambda: None) for _ in range(WAITING))
        assert not answers.route("rf/w/srv/state", None)(lambda: None)  # the lane is full
        assert counters["rate_limited"] == 1
        answers.route("rf/w/srv/state", None)  # the budget's last token
        with pytest.raises(ServiceError, match=f"^{RATE_LIMITED}: this sim answers srv/state"):
            answers.route("rf/w/srv/state", None)
        assert counters["rate_limited"] == 2
        clock.jump(1.0)
        assert answers.route("rf/w/srv/state", None) is not None  # a second later the budget is back
    finally:
        gate.set()
        answers.close()
