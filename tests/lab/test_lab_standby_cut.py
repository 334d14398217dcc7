"""A standby that loses its own link (its cable pulled, the router restarted) does not take the world over: it
cannot tell a dead primary from its own deafness, and a take-over from the state it had at the cut would step
down the primary that served everyone meanwhile (the world's epochs and joints going back). Once its link is back
and the primary's token with it, it follows the primary again."""

from __future__ import annotations

import pytest

import time

from robofabric.testing import RemoteRoles, wait_until
from robofabric.lab import Lab, LabProcess

pytestmark = [pytest.mark.lab, pytest.mark.slow]


def _world(lab: Lab):
    router_host, sa, sb = lab.add_host("router"), lab.add_host("sa"), lab.add_host("sb")
    ep = router_host.endpoint()
    router = router_host.start(["router", "--listen", ep], name="router")
    wait_until(lambda: "listening" in router.output() or not router.alive(), timeout=120, what="router listening")
    # the roles the sims show, watched from the router's host (a cut takes neither it nor its link)
    roles = RemoteRoles(router_host.python(name="roles"), "demo", ep)
    sim = ["sim", "--scene", "arm_cell", "--world", "demo", "--connect", ep]
    primary = sa.start([*sim, "--id", "sim-a"], name="sim-a")
    roles.wait("sim-a", "primary", term=1, timeout=120, seen=lambda: primary.output()[-800:])
    standby = sb.start([*sim, "--id", "sim-b", "--standby"], name="sim-b")
    roles.wait("sim-b", "standby", term=1, leader="sim-a", timeout=120, seen=lambda: standby.output()[-800:])
    return router_host, router, primary, standby


def _never(pred, seconds: float, what: str, seen) -> None:
    """``pred`` stays false for ``seconds`` (polled)."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        assert not pred(), f"{what}; seen: {seen()[-1500:]}"
        time.sleep(0.1)


def _no_take_over(primary: LabProcess, standby: LabProcess, seconds: float) -> None:
    _never(
        lambda: "took over" in standby.output() or "stepping down" in primary.output(),
        seconds,
        "a take-over",
        lambda: standby.output() + primary.output(),
    )


def test_a_standby_cut_off_past_the_lease_does_not_take_over(lab: Lab):
    _, _, primary, standby = _world(lab)
    lab.cut("sb")
    try:
        _no_take_over(primary, standby, 6.0)  # three transport leases cut off
    finally:
        lab.restore("sb")
    _no_take_over(primary, standby, 6.0)  # and once plugged back in
    assert primary.alive() and standby.alive()
    assert "took over" not in standby.output(), standby.output()[-1500:]
    assert "stepping down" not in primary.output(), primary.output()[-1500:]


def test_router_restarts_leave_the_primary_in_charge(lab: Lab):
    """Three restarts in a row, the first at once after the standby found its leader (no state of it yet): the
    tokens that go with the standby's link can reach it while its session still lists the router, and a restart
    can come while it waits for the others to come back (both made the standby take over in the lab)."""
    router_host, router, primary, standby = _world(lab)
    for n in range(3):
        router.kill()
        router = router_host.start(["router", "--listen", router_host.endpoint()], name=f"router{n + 2}")
        wait_until(lambda: "listening" in router.output() or not router.alive(), timeout=120, what="the router again")
        _no_take_over(primary, standby, 8.0 if n == 2 else 3.0)
    assert "took over" not in standby.output(), standby.output()[-1500:]
    assert "stepping down" not in primary.output(), primary.output()[-1500:]
