"""``robofabric bench paper``: its counting proxy agrees with the kernel, its payloads are what it says, and a
quick run through a real router and a real mosquitto gives one consistent document (figures go to docs)."""

from __future__ import annotations

import json
import math
import shutil
import socket
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from robofabric.testing import wait_until
from robofabric.bench.paper import PAYLOADS, count_numbers, make_payload
from robofabric.bench.paper_figures import PAPER
from robofabric.bench.wire import HEADER_BYTES, CountingProxy, ethernet_segments


def _sink() -> tuple[socket.socket, list[int], threading.Thread]:
    """A loopback server that reads one connection to its end, counting what it got."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    got = [0]

    def run() -> None:
        conn, _ = srv.accept()
        with conn:
            while data := conn.recv(65536):
                got[0] += len(data)

    t = threading.Thread(target=run, daemon=True)
    t.start()
    return srv, got, t


def test_the_proxy_counts_what_the_kernel_received_and_forwards_it_all():
    srv, got, t = _sink()
    with CountingProxy(srv.getsockname()) as proxy:
        client = socket.create_connection(("127.0.0.1", proxy.port))
        sent = 0
        for i in range(50):
            chunk = bytes([i]) * (100 + 37 * i)
            client.sendall(chunk)
            sent += len(chunk)
        wait_until(
            lambda: proxy.count().stream_bytes == sent,
            timeout=10,
            what="the proxy counted every byte",
            seen=lambda: proxy.count(),
        )
        (conn,) = proxy.connections()
        assert CountingProxy.kernel_bytes_received(conn) == sent  # the kernel's own count agrees
        c = proxy.count()
        assert 1 <= c.segments <= 50 + 3  # at most one per send plus the handshake's ACK
        assert c.wire_bytes == sent + HEADER_BYTES * c.segments
        client.close()
        wait_until(lambda: got[0] == sent, timeout=10, what="the server got every byte", seen=lambda: got[0])
        wait_until(lambda: not proxy.connections(), timeout=10, what="the proxy closed its side")
        assert proxy.count().segments >= c.segments  # a closed connection's segments stay counted
    t.join(timeout=5)
    srv.close()


def test_ethernet_segments():
    assert ethernet_segments(1) == 1 and ethernet_segments(1448) == 1 and ethernet_segments(1449) == 2
    assert ethernet_segments(4133) == 3


def test_the_paper_payload_is_415_numbers_of_135_rays_and_the_others_decode():
    from fabric.codec import decode
    from fabric.interfaces import JointState, Scan

    m = make_payload("paper-135", 7)
    doc = json.loads(m)
    assert count_numbers(m) == 415 and doc["n"] == len(doc["rays"]) == 135 and doc["seq"] == 7
    scan = decode(make_payload("rf-240", 3))
    assert isinstance(scan, Scan) and scan.ranges_mm.shape == (240,)
    joints = decode(make_payload("arm-joints", 3))
    assert isinstance(joints, JointState) and joints.q.shape == (6,)


def test_the_paper_figures_name_their_source_and_match_tables_2_and_3():
    rows = PAPER["data_usage"]
    assert [r["rate_hz"] for r in rows] == [10, 20, 50, 100, 200, 600]
    by_rate = {r["rate_hz"]: r for r in rows}
    assert by_rate[20]["mb_per_min_avg"] == 10.0590 and by_rate[20]["source"] == "Table 3, 20 Hz column"
    assert by_rate[600]["mb_per_min_avg"] == 139.28 and by_rate[600]["source"].startswith("Table 2")
    for r in rows:
        assert r["bytes_per_msg_implied"] == round(r["mb_per_min_avg"] * 1e6 / (r["rate_hz"] * 60))


@pytest.mark.slow
def test_a_quick_run_gives_one_consistent_document(tmp_path):
    assert shutil.which("mosquitto") or shutil.which("/usr/sbin/mosquitto"), (
        "mosquitto is required (.ci/run installs it)"
    )
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "robofabric",
            "bench",
            "paper",
            "--quick",
            "--json",
            "--rates",
            "50",
            "--duration",
            "1",
            "--plot",
            str(tmp_path / "mb.svg"),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    doc = json.loads(out.stdout)
    assert set(doc) >= {"data_usage", "paper", "machine"} and "resources" not in doc and "multi_user" not in doc
    rows = doc["data_usage"]
    assert [(r["transport"], r["payload"]) for r in rows] == [(t, p) for t in ("zenoh", "mqtt") for p in PAYLOADS]
    for r in rows:
        assert set(r) >= {
            "transport",
            "rate_hz",
            "payload",
            "payload_bytes_per_msg",
            "wire_bytes_per_msg",
            "mb_per_min_max",
            "mb_per_min_avg",
            "mb_per_min_min",
            "gb_per_hour",
        }
        assert r["rate_hz"] == 50 and r["sent"] == 50
        assert 0 < r["received"] <= r["sent"]
        assert r["received_bytes_per_msg"] == pytest.approx(
            r["payload_bytes_per_msg"], rel=0.05
        )  # what arrived is what was sent
        assert r["stream_bytes_per_msg"] >= r["payload_bytes_per_msg"]  # the protocol adds, never removes
        assert r["segments_per_msg"] > 0 and r["wire_bytes_per_msg"] > r["stream_bytes_per_msg"]  # headers on the wire
        assert r["windows"] == 2 and r["window_s"] == 0.5
        assert r["mb_per_min_min"] <= r["mb_per_min_avg"] <= r["mb_per_min_max"]
        assert r["gb_per_hour"] == pytest.approx(r["mb_per_min_avg"] * 60 / 1e3)
        assert not any(math.isnan(r[k]) for k in ("mb_per_min_max", "mb_per_min_avg", "mb_per_min_min"))
    svg = (tmp_path / "mb.svg").read_text()
    assert "zenoh, paper-135" in svg and "mqtt, arm-joints" in svg and "Tables 2-3" in svg


@pytest.mark.slow
def test_one_run_through_the_cli_gives_every_section_of_the_document():
    """``--resources --multi-user``: data usage, Table 4 from one launch (router, sim, compute, viewer, console,
    alice's Test A, bob's Test B) that ends by itself once both users finished, and the multi-user test, in one
    ``--json`` document beside the paper's figures; every application sampled, every student measured, and every
    process of both worlds ended."""
    from robofabric.bench.paper_resources import PEERS

    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "robofabric",
            "bench",
            "paper",
            "--quick",
            "--json",
            "--rates",
            "50",
            "--payloads",
            "arm-joints",
            "--transports",
            "zenoh",
            "--duration",
            "1",
            "--resources",
            "--multi-user",
            "--minutes",
            "0.25",
            "--students",
            "2",
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert out.returncode == 0, out.stderr[-3000:]
    doc = json.loads(out.stdout)
    assert set(doc) >= {"data_usage", "resources", "multi_user", "paper", "machine", "load_average"}
    assert [(r["transport"], r["rate_hz"], r["payload"]) for r in doc["data_usage"]] == [("zenoh", 50, "arm-joints")]
    assert doc["resources_run"]["up_exit"] == 0, doc["resources_run"]["up_log_tail"]  # both scenarios succeeded
    assert [r["peer"] for r in doc["resources"]] == list(PEERS)
    for r in doc["resources"]:
        assert r["samples"] >= 1, r
        assert 0.0 <= r["cpu_min"] <= r["cpu_max"] and 0.0 < r["rss_min_mb"] <= r["rss_max_mb"], r
    multi = doc["multi_user"]
    assert multi["students"] == 2 and [s["student"] for s in multi["per_student"]] == ["s0", "s1"]
    assert set(multi["per_student"][0]["received"]) == {"arm1", "base1"} and multi["per_student"][0]["messages"] > 0, (
        multi["per_student"]  # each student's errors, moves and losses: v1 of 2026-12-04 saw s0 receive nothing
    )
    assert 0 < multi["delay_ms_p50"] <= multi["delay_ms_p99"] and multi["paper_reported"] == PAPER["multi_user"]
    assert doc["paper"]["multi_user"]["delay_ms"] == 100.0
    from robofabric.testing import wait_until as wait

    wait(
        lambda: not any(_name_alive(p) for p in ("scenario", "--save", "student")),
        timeout=30,
        what="both worlds' peers to end",
    )


def _name_alive(word: str) -> bool:
    """A process of a bench-paper world (paper or multi + 6 hex digits) whose command line holds ``word``."""
    import os
    import re

    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                cmd = open(f"/proc/{d}/cmdline", "rb").read().decode(errors="replace").split("\0")
            except OSError:
                continue
            if word in cmd and any(re.fullmatch(r"(paper|multi)[0-9a-f]{6}", c) for c in cmd):
                return True
    return False


@pytest.mark.parametrize(
    "args, says",
    [
        (["--rates", "x"], "--rates 'x'"),
        (["--payloads", "scan"], "paper-135, rf-240, arm-joints"),
        (["--transports", "dds"], "zenoh, mqtt"),
        (["--duration", "1", "--window", "5"], "at most --duration"),
        (["--no-data-usage"], "nothing to run"),
        (["--multi-user", "--students", "1"], "--students at least 2"),
        (["--no-data-usage", "--multi-user", "--plot", "x.svg"], "needs --data-usage"),
    ],
)
def test_bad_options_are_refused_with_what_is_expected(args, says, capsys):
    from robofabric.cli import main  # in-process: the same exit code and message as the command's

    rc = main(["bench", "paper", *args])
    err = capsys.readouterr().err
    assert rc == 2 and says in err, (rc, err)


def test_a_failed_launch_keeps_its_peers_logs(tmp_path):
    """A failed run's cause is in its peers' logs, which go with the bench's temporary folder: they are copied out,
    and each one's tail is in the document."""
    from robofabric.bench.paper_resources import _kept_logs

    assert _kept_logs(tmp_path) == ""  # the launch never got as far as its logs
    logs = tmp_path / "out" / "logs"
    logs.mkdir(parents=True)
    (logs / "bob.log").write_text("x" * 5000 + "did not reach the end of its path")
    (logs / "sim.log").write_text("sim up")
    words = _kept_logs(tmp_path, tail=100)
    kept = Path(words.split("kept in ")[1].split("\n")[0])
    try:
        assert sorted(p.name for p in kept.iterdir()) == ["bob.log", "sim.log"]
        assert "--- bob.log:\n" in words and words.count("x") <= 100 and "did not reach" in words and "sim up" in words
    finally:
        shutil.rmtree(kept)
