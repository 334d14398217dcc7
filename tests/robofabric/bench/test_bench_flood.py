"""The issue-14 flood over real processes on loopback: an owner's commands and lease survive it, peers stay bounded.

A router, a sim and a compute peer (``robofabric`` child processes), alice commanding
arm1 every 50 ms, and a flooder process sending the issue's load once, as fast as it can: 20,000
commands to unique robot ids, 10,000 junk payloads on each of the 8 keys the peers subscribe to
(plus junk queries on ownership and IK), 100 payloads of 5 MB, 1,000 fake joint streams for the
compute peer and 1,000 forged ownership requests. Pass criteria are the issue's, measured at the
process level (/proc); see robofabric.bench.flood for how a command is known to be applied. Two seconds
into the flood alice sets the arm off slowly towards a far target and stops it: the stop must take effect
within 1 s, short of the target (user_peer.reliable.resend_until re-sends it until the arm is seen still).
"""

from __future__ import annotations

import pytest

from robofabric.bench.flood import Load, run_flood


@pytest.mark.slow
def test_an_owner_is_not_starved_and_peers_stay_bounded_under_the_flood(tmp_path):
    r = run_flood(Load(), tmp_path)
    report = r.summary()
    assert r.flooder.get("unique_commands") == 20_000 and r.flooder.get("forged_requests") == 1_000, report
    assert r.commands >= 100, report
    # alice's commands applied, none starved: p99 within 2 s. The 0.5 s is the benchmark's figure on a quiet
    # box (`robofabric bench flood`, docs/benchmarks.md: 50.5 ms); the suite on four workers beside it once gave 0.64 s
    assert r.pct(99) <= 2.0, report
    assert not r.lapses, report  # her lease never lapsed (nobody else ever owned arm1)
    # the flood reached the sim, not only the flooder's socket: its own count of refused commands (the
    # unique-id ones are each refused, from the key alone), printed when it stops
    # 7.5k of the 20k on a quiet 2-core box (zenoh drops on congestion); 1,588 beside two CPU hogs (load 12-17), the
    # flooder starved too: 1,000 (5 %) still shows the flood reached the sim
    assert r.sim_counts.get("rejected", 0) >= 1_000, report
    # mid-flood, alice sets the last joint off slowly towards a target ~15 s away, then stops the arm: cmd/stop
    # sent again every 0.1 s until her joint stream shows it still. It must take effect within 1 s of the first
    # send and leave the joint well short of the target: a lost stop leaves it moving
    assert r.stop.get("moving") and r.stop.get("flooder_running"), report
    assert r.stop.get("done") and r.stop["effect_s"] <= 1.0 and r.stop["short_by"] >= 1.0, report
    for peer in ("sim", "compute"):
        assert r.growth(peer) <= 50.0, report  # resident memory grew by at most 50 MB
        assert r.log_bytes[peer] <= 1_000_000, report  # each log file stays under 1 MB
