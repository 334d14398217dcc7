"""Each login's budgets at the authority (ownership.admission): requests to their lane, renewals at once, excess refused."""

from __future__ import annotations

from collections import Counter

import pytest

from fabric import keys
from fabric.budget import RATE_LIMITED, Rate
from fabric.interfaces import OwnRequest, ServiceError
from fabric.rate import FakeClock
from ownership.admission import Admission, OwnBudgets


def _admission(budgets: OwnBudgets):
    reported, counters, session = [], {}, Counter()
    adm = Admission(
        budgets,
        FakeClock(),
        counters,
        report=lambda limit, make: reported.append((make(), limit)),
        fabric_counters=session,
    )
    return adm, reported, counters, session


def test_requests_go_to_the_lane_renewals_are_answered_at_once_and_the_excess_is_refused():
    adm, reported, counters, session = _admission(OwnBudgets(requests=Rate(1.0, 3.0)))
    try:
        mallory = keys.own_request("w", "base1", "mallory")
        req = OwnRequest("request", "mallory")
        assert all(callable(adm.route(mallory, req)) for _ in range(3))  # her burst, each to the lane
        with pytest.raises(ServiceError) as refused:
            adm.route(mallory, req)
        assert refused.value.reason.startswith(f"{RATE_LIMITED}: mallory")
        assert counters["rate_limited"] == session["rate_limited"] == 1 and adm.refused() == {"mallory": 1}
        ev, limit = reported[0]
        assert (ev.object, ev.user, limit) == ("base1", "mallory", "rate_limited:base1")
        # her renewals and releases are her own lane's (answered at once, apart), and bob's requests are his
        assert adm.route(mallory, OwnRequest("renew", "mallory")) is None
        assert adm.route(mallory, OwnRequest("release", "mallory")) is None
        assert adm.route(keys.own_request("w", "base1", "mallory"), None) is None  # a record query
        assert callable(adm.route(keys.own_request("w", "base1", "bob"), OwnRequest("request", "bob")))
    finally:
        adm.close()


def test_budgets_parse_with_defaults_for_what_is_not_given():
    b = OwnBudgets.parse("requests=2/4, renewals=50")
    assert (b.requests, b.owner, b.queries) == (Rate(2, 4), Rate(50, 100), OwnBudgets().queries)
    assert OwnBudgets.parse("") == OwnBudgets()
    for bad in ("requests", "speed=3", "queries=0"):
        with pytest.raises(ValueError):
            OwnBudgets.parse(bad)


def test_past_all_budgets_together_a_login_is_refused_before_decoding():
    from fabric.codec import decode

    adm, reported, counters, _ = _admission(
        OwnBudgets(requests=Rate(1.0, 1.0), owner=Rate(1.0, 1.0), queries=Rate(1.0, 1.0))
    )
    try:
        key = keys.own_request("w", "arm1", "mallory")
        assert [adm.gate(key) for _ in range(3)] == [None] * 3
        refusal = adm.gate(key)
        assert (
            decode(refusal).reason.startswith(f"{RATE_LIMITED}: mallory") and adm.gate(key) is refusal
        )  # encoded once
        assert adm.gate(keys.own_request("w", "arm1", "bob")) is None
        assert counters["rate_limited"] == 2 and reported[0][1] == "rate_limited:arm1"
    finally:
        adm.close()
