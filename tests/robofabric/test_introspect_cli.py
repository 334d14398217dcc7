"""``robofabric list``, ``info KEY`` and ``interfaces`` against a live world (real router, real publishers)."""

from __future__ import annotations

import json
import re
import subprocess
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from fabric import keys
from robofabric.introspect import KeyObserver, source_of
from fabric.codec import encode
from fabric.interfaces import Header, JointState, OccupancyGrid
from robofabric.testing import robofabric_cmd, wait_until

NAMES = ("j1", "j2")


AT_ONCE = 3
"""Commands run at the same time: each spends most of its wall waiting (start-up, its ``--duration``), but the box
has two cores, and more at once would load it for the other tests beside this one."""


def _cli_at_once(
    *commands: tuple[str, ...], env: dict[str, str] | None = None, timeout: float = 90
) -> list[subprocess.CompletedProcess]:
    """Run ``robofabric`` commands, :data:`AT_ONCE` at a time, each its own process; what each printed, in order.

    Each only reads the live world (none changes what another sees) and spends most of its wall waiting: a second
    or more of start-up, then its ``--duration`` of listening. One after another they took ~40 s of this file's ~50.
    ``subprocess.run`` ends a process that runs past ``timeout``; the pool waits for every one."""

    def run(args: tuple[str, ...]) -> subprocess.CompletedProcess:
        return subprocess.run(robofabric_cmd(*args), capture_output=True, text=True, timeout=timeout, env=env)

    with ThreadPoolExecutor(max_workers=AT_ONCE) as pool:
        return list(pool.map(run, commands))


def test_observer_counts_rates_types_and_publishers_from_the_payload():
    obs = KeyObserver()
    for i in range(11):
        obs.add(
            "rf/w/robot/a/joints",
            encode(JointState(NAMES, np.zeros(2), np.zeros(2), Header(seq=i, source="sim-7"))),
            10.0 + 0.1 * i,
        )
    obs.add("rf/w/map/map", encode(OccupancyGrid(0.1, np.zeros(3), np.zeros((2, 2), dtype=np.uint8))), 10.5)
    obs.add("rf/w/event/x", b"\x00raw", 10.6)
    ev, grid, joints = obs.snapshot()  # sorted by key
    assert (joints.types, joints.publishers, joints.messages) == (("JointState",), ("sim-7",), 11)
    assert joints.rate_hz == pytest.approx(10.0) and not joints.latched
    assert grid.latched and grid.rate_hz == 0.0 and grid.publishers == ()
    assert ev.types == ("raw",) and source_of(b"\x00raw") == ""


def test_publishers_are_read_from_headers_of_any_version():
    """A sim's header carries a sixth field (its authority term); a later version may append more."""
    import msgpack

    obs = KeyObserver()
    obs.add(
        "rf/w/robot/a/joints",
        encode(JointState(NAMES, np.zeros(2), np.zeros(2), Header(seq=1, source="sim-a", term=3))),
        1.0,
    )
    later = msgpack.unpackb(
        encode(JointState(NAMES, np.zeros(2), np.zeros(2), Header(seq=2, source="sim-b", term=4))), raw=False
    )
    later[-1] = [*later[-1], "a field of a later version"]
    obs.add("rf/w/robot/a/joints", msgpack.packb(later, use_bin_type=True), 1.1)
    (joints,) = obs.snapshot()
    assert joints.types == ("JointState",) and joints.publishers == ("sim-a", "sim-b")


@pytest.fixture
def live_world(router, connect, world):
    """A publisher of an arm's joints at ~50 Hz and a latched map, until the test ends."""
    pub = connect("tool", peer_id="sim-test")
    pub.publish(
        keys.map_key(world, "map"),
        OccupancyGrid(0.1, np.zeros(3), np.zeros((4, 4), dtype=np.uint8), Header(source="sim-test")),
    )
    stop = threading.Event()

    def run() -> None:
        i = 0
        while not stop.wait(0.02):
            pub.publish(
                keys.robot_joints(world, "arm1"),
                JointState(NAMES, np.full(2, 0.01 * i), np.zeros(2), Header.now(seq=i, source="sim-test")),
            )
            i += 1

    t = threading.Thread(target=run, daemon=True)
    t.start()
    yield f"tcp/127.0.0.1:{router[1]}"
    stop.set()
    t.join(timeout=5)


@pytest.mark.slow
def test_list_info_and_interfaces_against_a_live_world(live_world, world):
    ep = live_world
    live = ("--world", world, "--connect", ep)
    # at once: each list/info shows the others' subscriptions, and nothing here asserts on subscribers
    out, only, info, info_map, types_out, scan_out, bad = _cli_at_once(
        ("list", "--json", "--duration", "2", *live),
        ("list", "robot/**", "--json", "--duration", "1", *live),
        ("info", "robot/arm1/joints", "--duration", "1.5", *live),
        ("info", "map/map", "--json", "--duration", "1", *live),
        ("interfaces", "--json"),
        ("interfaces", "Scan", "--json"),
        ("interfaces", "Nope"),
    )
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
    by_key = {k["key"]: k for k in doc["keys"]}
    j = by_key[keys.robot_joints(world, "arm1")]
    assert (
        j["type"] == "JointState" and j["publishers"] == ["sim-test"] and 10 < j["rate_hz"] < 200 and not j["latched"]
    )
    m = by_key[keys.map_key(world, "map")]
    assert m["type"] == "OccupancyGrid" and m["latched"]  # published before list started: the latched value

    only = json.loads(only.stdout)
    assert [k["key"] for k in only["keys"]] == [keys.robot_joints(world, "arm1")]

    assert info.returncode == 0, info.stderr
    assert (
        "type JointState" in info.stdout and "publishers sim-test" in info.stdout and "names: string[]" in info.stdout
    ), info.stdout
    info_json = json.loads(info_map.stdout)
    assert info_json["latched"] is True and info_json["types"]["OccupancyGrid"][:3] == ["resolution", "origin", "cells"]

    types = json.loads(types_out.stdout)["types"]
    names = {t["name"] for t in types}
    assert {
        "JointState",
        "Scan",
        "OccupancyGrid",
        "WorldInfo",
        "IKRequest",
        "PlanRequest",
    } <= names  # plugins' types too
    scan = json.loads(scan_out.stdout)
    assert [f["name"] for f in scan["fields"]] == ["angle_min", "angle_increment", "range_max", "ranges_mm", "header"]
    assert scan["fields"][3]["type"] == "uint16[]"
    assert bad.returncode == 2 and "unknown message type 'Nope'" in bad.stderr


@pytest.fixture
def peers_world(router, connect, world):
    """A sim-like peer (publishes joints with a term-3 header, takes commands, serves srv/world), a compute-like
    peer serving IK, and tokens no peer could name: what any login may declare."""
    from fabric.interfaces import WorldInfo

    sim = connect("sim", peer_id="sim-x")
    comp = connect("compute", peer_id="compute-x")
    sim.subscribe_raw(keys.robot_cmd_all(world, "arm1"), lambda s: None)
    sim.rpc.serve(keys.srv(world, "world"), lambda k, r: WorldInfo(world=world))
    comp.rpc.serve(keys.srv_per_subject(world, "ik"), lambda k, r: None)
    odd = connect("tool", peer_id="mallory-tool")
    tokens = [
        odd.session.liveliness().declare_token(f"rf/{world}/peer/viewer/with space"),
        odd.session.liveliness().declare_token(f"rf/{world}/peer/nokind/x"),
        odd.session.liveliness().declare_token(f"rf/{world}/peer/viewer/a/b"),
    ]
    stop = threading.Event()

    def run() -> None:
        i = 0
        while not stop.wait(0.02):
            sim.publish(
                keys.robot_joints(world, "arm1"),
                JointState(NAMES, np.zeros(2), np.zeros(2), Header.now(seq=i, source="sim-x", term=3)),
            )
            i += 1

    t = threading.Thread(target=run, daemon=True)
    t.start()
    yield f"tcp/127.0.0.1:{router[1]}"
    stop.set()
    t.join(timeout=5)
    for tok in tokens:
        tok.undeclare()


@pytest.mark.slow
def test_ps_list_and_info_name_publishers_subscribers_and_services_and_skip_bad_tokens(peers_world, world):
    live = ("--world", world, "--connect", peers_world)
    # ps only asks (tokens, the router's admin space): those run at once. list and info subscribe, and a subscriber
    # is what they show: each of those runs alone, as a user would run it
    ps, ps_json, ps_v, text, srv = _cli_at_once(
        ("ps", *live),
        ("ps", "--json", *live),
        ("ps", "-v", "sim-x", "--json", *live),
        ("ps", "-v", "compute-x", *live),
        ("list", "--services", "--json", *live),
    )
    (lst,), (w,), (cmd,) = (
        _cli_at_once(args)
        for args in (
            ("list", "robot/**", "--json", "--duration", "1", *live),
            ("info", "srv/world", "--duration", "0.5", *live),
            ("info", "robot/arm1/cmd/joints/by/alice", "--json", "--duration", "0.5", *live),
        )
    )
    assert ps.returncode == 0, ps.stderr
    assert "sim-x" in ps.stdout and "compute-x" in ps.stdout and "Traceback" not in ps.stderr
    assert f"'rf/{world}/peer/viewer/with space'" in ps.stderr, ps.stderr
    doc = json.loads(ps_json.stdout)
    assert doc["peers"]["sim"] == ["sim-x"] and len(doc["bad_tokens"]) == 2, (
        doc
    )  # peer/viewer/a/b is not a peer/KIND/ID key at all

    v = json.loads(ps_v.stdout)
    assert v["declarations_visible"] and list(v["info"]) == ["sim-x"], v
    info = v["info"]["sim-x"]
    assert info["publishes"] == [keys.robot_joints(world, "arm1")]
    assert keys.robot_cmd_all(world, "arm1") in info["subscribes"] and info["serves"] == [keys.srv(world, "world")], (
        info
    )
    assert text.returncode == 0 and f"rf/{world}/srv/ik/*  (IKRequest -> IKReply)" in text.stdout, (
        text.stdout + text.stderr
    )

    (j,) = json.loads(lst.stdout)["keys"]
    assert j["publishers"] == ["sim-x"] and j["subscribers"] == [], j
    srv = json.loads(srv.stdout)
    assert {(s["key"], s["request"], s["reply"], tuple(s["servers"])) for s in srv["services"]} == {
        (keys.srv(world, "world"), "-", "WorldInfo", ("sim-x",)),
        (f"rf/{world}/srv/ik/*", "IKRequest", "IKReply", ("compute-x",)),
    }
    assert w.returncode == 0 and "reply WorldInfo; served by sim-x" in w.stdout and "no message" not in w.stdout, (
        w.stdout
    )
    cmd = json.loads(cmd.stdout)
    assert cmd["subscribed_by"] == ["sim-x"], cmd


LONG = "arm_with_a_name_long_enough_to_need_folding_in_a_narrow_terminal"
ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")


def read_down(text: str) -> str:
    """The first column of a table as printed, read downwards (a folded key comes out whole), whatever the
    layout: a boxed table (cells between │), a borderless one (the column as wide as its header's gap), or
    rows printed as blocks (the first cell on lines of its own, each other cell indented)."""
    lines = [line for line in text.splitlines() if line.strip()]
    if any("│" in line for line in lines):
        return "".join(cells[1].strip() for line in lines if len(cells := line.split("│")) > 2)
    rule = next((i for i, line in enumerate(lines) if set(line.strip()) == {"─"}), None)
    if rule is not None:  # borderless: the header line above the rule gives the first column's width
        header = lines[rule - 1]
        width = len(header) - len(header[len(header.split()[0]) :].lstrip()) - 3
        return "".join(line[:width].strip() for line in lines[rule + 1 :])
    return "".join(line.strip() for line in lines[1:] if not line.startswith("  "))


def words(text: str) -> set[str]:
    return set(re.split(r"[\s│┃,]+", text))


@pytest.mark.slow
@pytest.mark.parametrize("width", [60, 80, 120])
def test_tables_fit_the_terminal_with_no_column_or_word_cut(peers_world, world, connect, width):
    """list, list --services, info, ps, ps -v, own list and interfaces never print a line wider than the terminal,
    drop no column and cut no word: ids and types whole, keys whole when read down their column (list
    at 80 columns keeps its msgs and kB/s columns and its peer ids whole). In a pipe ($COLUMNS) and on a
    terminal (its size)."""
    import os

    pub = connect("sim", peer_id="sim-long")
    stop = threading.Event()

    def run() -> None:
        i = 0
        while not stop.wait(0.02):
            pub.publish(
                keys.robot_joints(world, LONG),
                JointState(NAMES, np.zeros(2), np.zeros(2), Header.now(seq=i, source="sim-long")),
            )
            i += 1

    t = threading.Thread(target=run, daemon=True)
    t.start()
    ep = peers_world
    env = {**os.environ, "COLUMNS": str(width)}

    live = ("--world", world, "--connect", ep)

    def shown(out: subprocess.CompletedProcess) -> str:
        assert out.returncode == 0, out.stderr
        wide = [line for line in (out.stdout + out.stderr).splitlines() if len(line) > width]
        assert not wide, wide
        return out.stdout

    try:
        # what the commands below show is there before the first starts (run one after another, the first one's
        # second of listening gave the publisher that time)
        wait_until(
            lambda: pub.counters["published"] and ("sim", "sim-long") in pub.live_peers("sim"),
            what="sim-long's token and joints",
        )
        # what only asks (ps, services, types) runs at once; list and info subscribe, which is what they show: alone
        asking = [("ps", *live), ("ps", "-v", "sim-long", *live), ("list", "--services", *live), ("interfaces",)]
        docs = [("ps", "--json", *live), ("ps", "-v", "--json", *live)] if width == 60 else []
        outs = _cli_at_once(*asking, *docs, env=env)
        ps, ps_v, services, types = (shown(out) for out in outs[: len(asking)])
        table, info = (
            shown(*_cli_at_once(args, env=env))
            for args in (("list", "--duration", "1", *live), ("info", f"robot/{LONG}/joints", "--duration", "1", *live))
        )
        if width == 60:
            docs += [
                ("list", "--json", "--duration", "1", *live),
                ("info", f"robot/{LONG}/joints", "--json", "--duration", "1", *live),
            ]
            outs += [out for args in docs[-2:] for out in _cli_at_once(args, env=env)]
        for head in (
            "type",
            "publishers",
            "subscribers",
            "rate",
            "Hz",
            "msgs",
            "kB/s",
        ):  # the key is each row's first line
            assert head in words(table) or f"{head}:" in words(table), (head, table)
        assert {"sim-long", "sim-x", "JointState"} <= words(table), table
        assert keys.robot_joints(world, LONG) in read_down(table), table
        assert LONG in "".join(info.split())
        assert {"sim-x", "sim-long"} <= words(ps)
        assert keys.robot_joints(world, LONG) in "".join(ps_v.split())
        assert keys.srv(world, "world") in read_down(services) and {"WorldInfo", "IKRequest", "IKReply"} <= words(
            services
        ), services
        assert {"JointState", "fabric.interfaces.std", "OccupancyGrid"} <= words(types), types
        # a description is whole (it was cut at 90 characters): its last words are there (BaseInfo's ends "(plans for it may reverse).")
        assert "reverse)." in words(types) and "``" not in types, types
        if width == 80:  # on a terminal of that size, no $COLUMNS: the same
            term = _on_a_terminal(robofabric_cmd("list", "--duration", "1", *live), cols=width)
            assert max(len(line) for line in term.splitlines()) <= width, term
            assert {"sim-long", "sim-x", "msgs", "kB/s"} <= words(term), term
        if width == 60:
            for args, out in zip(docs, outs[len(asking) :], strict=True):
                doc = json.loads(out.stdout)  # one document, whatever the width: no folding, no markup
                assert isinstance(doc, dict) and "\x1b" not in out.stdout, args
            (lst,) = _cli_at_once(("list", "--json", "--duration", "1", *live))  # no $COLUMNS at all
            long_key = next(k for k in json.loads(lst.stdout)["keys"] if k["key"] == keys.robot_joints(world, LONG))
            assert set(long_key) == {
                "key",
                "type",
                "publishers",
                "subscribers",
                "messages",
                "rate_hz",
                "bytes_per_s",
                "last_bytes",
                "latched",
            }
            assert long_key["publishers"] == ["sim-long"]
    finally:
        stop.set()
        t.join(timeout=5)


def _on_a_terminal(argv: list[str], *, cols: int) -> str:
    """What ``argv`` prints on a pseudo-terminal ``cols`` wide ($COLUMNS unset), ANSI styling removed."""
    import fcntl
    import os
    import pty
    import struct
    import termios

    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 50, cols, 0, 0))
    env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES")}
    proc = subprocess.Popen(argv, stdin=slave, stdout=slave, stderr=slave, env=env, start_new_session=True)
    os.close(slave)
    chunks = []
    try:
        while True:
            try:
                data = os.read(master, 65536)
            except OSError:  # the child closed the terminal
                break
            if not data:
                break
            chunks.append(data)
    finally:
        proc.wait(timeout=90)
        os.close(master)
    assert proc.returncode == 0, b"".join(chunks)
    return ANSI.sub("", b"".join(chunks).decode(errors="replace")).replace("\r", "")
