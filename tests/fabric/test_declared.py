"""A peer tells what it subscribes to and serves on its token's key (fabric.declared): the codec, the bookkeeping,
and a live world whose router has no admin space at all (what ``list``, ``info`` and ``ps -v`` read)."""

from __future__ import annotations

import dataclasses
import json

import zenoh
from hypothesis import given
from hypothesis import strategies as st

from fabric import keys
from fabric.declared import Declared, Told, decode_told, encode_told, is_declared
from fabric.session import Fabric
from robofabric.declarations import read_declarations
from robofabric.testing import client, free_port, router_config, wait_until

exprs = st.lists(st.text(min_size=1, max_size=40), max_size=8, unique=True).map(lambda v: tuple(sorted(v)))


@given(kind=st.text(max_size=10), ident=st.text(max_size=10), subs=exprs, served=exprs)
def test_an_answer_reads_back_as_told(kind: str, ident: str, subs: tuple[str, ...], served: tuple[str, ...]) -> None:
    told = Told(kind, ident, subs, served)
    assert decode_told(encode_told(told)) == told


def test_a_made_up_answer_is_none_and_odd_entries_are_left_out() -> None:
    for payload in (b"", b"\xff\xfe", b"[]", b"null", b'{"kind": "sim"}', b'{"kind": 1, "id": "a"}'):
        assert decode_told(payload) is None, payload
    no_list = {"kind": "sim", "id": "a", "subscribers": "rf/w/**", "queryables": []}
    assert decode_told(json.dumps(no_list).encode()) is None
    odd = {"kind": "sim", "id": "a", "subscribers": ["b", 3, None, "", "a", "a", "x" * 5000], "queryables": []}
    assert decode_told(json.dumps(odd).encode()) == Told("sim", "a", ("a", "b"), ())


def test_what_was_undeclared_is_no_longer_told() -> None:
    conf = zenoh.Config()
    conf.insert_json5("scouting/multicast/enabled", "false")
    with zenoh.open(conf) as session:
        d = Declared()
        kept = session.declare_subscriber("rf/w/robot/a/joints", lambda s: None)
        gone = session.declare_subscriber("rf/w/robot/b/joints", lambda s: None)
        served = session.declare_queryable("rf/w/srv/world", lambda q: None)
        d.add("subscriber", "rf/w/robot/a/joints", kept)
        d.add("subscriber", "rf/w/robot/b/joints", gone)
        d.add("queryable", "rf/w/srv/world", served)
        assert d.now() == (("rf/w/robot/a/joints", "rf/w/robot/b/joints"), ("rf/w/srv/world",))
        gone.undeclare()
        assert not is_declared(gone) and is_declared(kept)
        assert d.now() == (("rf/w/robot/a/joints",), ("rf/w/srv/world",))
        for i in range(200):  # a page following robot after robot: what went does not pile up
            sub = session.declare_subscriber(f"rf/w/robot/x{i}/joints", lambda s: None)
            d.add("subscriber", f"rf/w/robot/x{i}/joints", sub)
            sub.undeclare()
        assert len(d._items) < 70
        assert d.now() == (("rf/w/robot/a/joints",), ("rf/w/srv/world",))


def test_peers_tell_their_declarations_through_a_router_with_no_admin_space() -> None:
    """The router's admin space can stop a router for good (zenoh 1.10.2, fabric/declared.py): the tools no longer ask
    it. Here it is off, and ``read_declarations`` still names who subscribes and serves, leaves out what was undeclared
    and the reader's own, and takes an answer that lies about whose it is as a bad token."""
    world, port = f"d{free_port()}", free_port()
    cfg = dataclasses.replace(router_config(world, port), extra=(("adminspace/enabled", "false"),))
    made: list[Fabric] = []
    router = Fabric(cfg, kind="router", peer_id="router")
    try:
        sim = client(world, port, kind="sim", peer_id="sim-a")
        made.append(sim)
        reader = client(world, port, kind="tool", peer_id="reader")
        made.append(reader)
        cmd = sim.subscribe_raw(keys.robot_cmd_all(world, "arm1"), lambda s: None)
        sim.subscribe_raw(keys.robot_joints(world, "arm2"), lambda s: None)
        sim.rpc.serve(keys.srv(world, "world"), lambda k, r: None)
        reader.subscribe_raw(keys.world_all(world), lambda s: None)
        # a login that answers on a peer's key in another peer's name
        fake = zenoh.open(client_config_of(reader))
        lie = fake.declare_queryable(
            keys.peer(world, "viewer", "v1"),
            lambda q: q.reply(
                keys.peer(world, "viewer", "v1"), encode_told(Told("sim", "sim-a", ("rf/forged/**",), ()))
            ),
        )
        assert [str(r.ok.key_expr) for r in reader.session.get("@/*/router", timeout=1.0) if r.ok is not None] == []

        decl = wait_until(
            lambda: (d := read_declarations(reader.session, world)).available and d.bad_tokens and d,
            timeout=20,
            what="the sim and the liar answering",
            seen=lambda: read_declarations(reader.session, world),
        )
        assert sorted(decl.told) == ["router", "sim-a"] and decl.told["sim-a"].kind == "sim", decl
        assert decl.of_peer("router") == ([], [])
        assert decl.of_peer("sim-a") == (
            sorted([keys.robot_cmd_all(world, "arm1"), keys.robot_joints(world, "arm2")]),
            [keys.srv(world, "world")],
        )
        assert decl.of_peer("reader") is None and decl.of_peer("v1") is None
        assert decl.bad_tokens == [keys.peer(world, "viewer", "v1")]
        assert decl.matching(decl.subscribers, keys.robot_cmd(world, "arm1", "joints", "alice")) == ["sim-a"]

        cmd.undeclare()
        subs, served = read_declarations(reader.session, world).of_peer("sim-a") or ([], [])
        assert subs == [keys.robot_joints(world, "arm2")] and served == [keys.srv(world, "world")]
        lie.undeclare()
        fake.close()
    finally:
        for f in made:
            f.close()
        router.close()


def client_config_of(fab: Fabric) -> zenoh.Config:
    return fab.config.zenoh_config()
