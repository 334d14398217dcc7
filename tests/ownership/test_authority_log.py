"""Every expiry is logged by the authority with its reason: an owner who stops renewing while
another owner's renewals keep arriving loses her robot, and the sim's log says whose lease, and how long
it went without a renewal."""

from __future__ import annotations

import logging
import re

from fabric import keys
from fabric.interfaces import OwnReply, OwnRequest
from robofabric.testing import wait_until

from ownership import Authority, OwnershipClient


def test_an_expiry_is_logged_with_its_reason(connect, world, caplog):
    auth = Authority(
        connect("sim", "host"), {"arm": "exclusive", "base": "exclusive"}, lease_s=0.6, grace_s=5.0
    ).start()
    bob = OwnershipClient(connect("user", "bob"), "bob", renew_s=0.1).start()
    alice = connect("user", "alice")  # asks once and never renews
    try:
        with caplog.at_level(logging.WARNING, logger="robofabric"):
            assert bob.request("base").granted
            reply = alice.rpc.call(
                keys.own_request(world, "arm", "alice"), OwnRequest("request", "alice"), expected=OwnReply
            )
            assert reply.outcome == "granted"
            wait_until(lambda: auth.records()["arm"].owner == "", timeout=10, what="alice's lease to expire")
            wait_until(lambda: "own_expired" in caplog.text, timeout=5, what="the expiry logged")
        line = next(r.getMessage() for r in caplog.records if "own_expired" in r.getMessage())
        assert re.search(r"lease of arm \(alice\) expired: no renewal for \d+\.\d s", line), line
        assert auth.records()["base"].owner == "bob"  # bob kept renewing: his lease never ran out
    finally:
        bob.close()
        auth.close()
