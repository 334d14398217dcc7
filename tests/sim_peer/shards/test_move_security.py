"""Moves are the staff's, and a move_in serves only what its source handed out (srv/state answers
no student): a `secure init` class world behind a real router, two sims as shards (sim-a: base0 of alice and base2;
sim-b: base1 of bob), each with its own sim login, an instructor (carol) and a lying student (mallory).

mallory tries what the issue did: `own move` with her login, and by hand on srv/state (every login may ask it)
and on srv/move in her name and in carol's: steal (a record rewritten to her), vanish (a move to a sim that does
not exist), kill a shard (a type no sim has), clone (alice's base0 into sim-b at term 100), phantom (a robot that
never existed, 0.9 m before bob's base) and code execution (a type that is a path to her own robot.toml, whose
hooks write a marker file). Each fails with a reason, and alice's and bob's robots, records and sims stay as they
were. carol's bad moves are refused by the sims too; her good one moves base2.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import uuid
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from fabric import keys
from fabric.config import FabricConfig
from fabric.interfaces import Event, RobotState, ServiceError, WorldInfo, WorldState
from robofabric.secure import init
from fabric.session import Fabric
from robofabric.testing import ProcessGroup, free_port, robofabric_cmd, wait_until
from robots.description import SceneRobot
from sim_peer.shards import handoff as ho

pytestmark = pytest.mark.slow

SIM_A = ("--scene", "warehouse", "--no-scene-robots", "--robot", "reeman:base0@0,0", "--robot", "reeman:base2@0,1")
SIM_B = ("--scene", "warehouse", "--no-scene-robots", "--robot", "reeman:base1@1.5,0,180")
PLANAR2 = Path(__file__).parents[1] / "plugin_robots" / "planar2"
STAFF_ONLY = "moves are for the instructor and sim logins"


class Class:
    """The router, two sims and the logins' sessions; what every test checks stays as it was."""

    def __init__(self, tmp: Path, procs: ProcessGroup) -> None:
        self.tmp, self.procs = tmp, procs
        self.world = f"m{uuid.uuid4().hex[:8]}"
        ep = f"tcp/127.0.0.1:{free_port()}"
        self.files = init(
            tmp / "class",
            users=["alice", "bob", "mallory"],
            instructors=["carol"],
            sims=["sim-a", "sim-b"],
            listen=[ep],
        ).clients
        self.router = procs.start(
            robofabric_cmd(
                "router", "--zenoh-config", str(tmp / "class" / "router.json5"), "--audit", "--audit-every", "1"
            ),
            name="router",
        )
        wait_until(
            lambda: "listening" in procs.output(self.router),
            timeout=30,
            what="router",
            seen=lambda: procs.output(self.router),
        )
        self.fabrics: list[Fabric] = []
        self.probe = self.fabric("viewer", "viewer", "probe")
        self.sim_a = self.start("sim-a", "sim", *SIM_A, "--id", "sim-a")
        wait_until(
            lambda: "sim-a" in self.parts(),
            timeout=90,
            what="sim-a serving",
            seen=lambda: procs.output(self.sim_a)[-1500:],
        )
        self.sim_b = self.start("sim-b", "sim", *SIM_B, "--id", "sim-b")
        wait_until(
            lambda: set(self.parts()) == {"sim-a", "sim-b"},
            timeout=90,
            what="both sims serving",
            seen=lambda: procs.output(self.sim_b)[-1500:],
        )

    def fabric(self, login: str, kind: str = "user", peer_id: str | None = None) -> Fabric:
        fab = Fabric(
            FabricConfig(world=self.world, config_file=str(self.files[login])), kind=kind, peer_id=peer_id or login
        )
        self.fabrics.append(fab)
        return fab

    def start(self, login: str, *args: str):
        return self.procs.start(
            robofabric_cmd(*args, "--world", self.world, "--zenoh-config", str(self.files[login])), name=login
        )

    def cli(self, login: str, *args: str) -> subprocess.CompletedProcess:
        return subprocess.run(
            robofabric_cmd(*args, "--world", self.world, "--zenoh-config", str(self.files[login])),
            capture_output=True,
            text=True,
            timeout=120,
        )

    def parts(self) -> dict[str, list[str]]:
        try:
            replies = self.probe.rpc.query(
                keys.srv(self.world, "world"), timeout=3.0, expected=WorldInfo, all_replies=True
            )
        except ServiceError:
            return {}
        return {r.source: sorted(x.id for x in r.message.robots) for r in replies}

    def sims_output(self) -> str:
        return self.procs.output(self.sim_a) + self.procs.output(self.sim_b)


@pytest.fixture(scope="module")
def cls(tmp_path_factory):
    import user_peer

    tmp = tmp_path_factory.mktemp("moves")
    with ProcessGroup(tmp) as procs:
        c = Class(tmp, procs)
        c.alice = user_peer.connect(world=c.world, zenoh_config=str(c.files["alice"]), timeout=10.0)
        c.bob = user_peer.connect(world=c.world, zenoh_config=str(c.files["bob"]), timeout=10.0)
        try:
            for who, rid in ((c.alice, "base0"), (c.bob, "base1")):
                r = who.robot(rid)
                r.wait_for("pose", timeout=30)
                r.request(timeout=10)
            c.epochs = {
                "base0": c.alice.ownership.record("base0").epoch,
                "base1": c.bob.ownership.record("base1").epoch,
            }
            c.marker = tmp / "mallory-was-here"
            c.evil = _evil_robot(tmp / "mallory" / "evil", c.marker)
            yield c
        finally:
            c.alice.close()
            c.bob.close()
            for fab in c.fabrics:
                fab.close()


def _evil_robot(folder: Path, marker: Path) -> Path:
    """mallory's own robot.toml with ``hooks = "hooks.py:Evil"``: importing it writes ``marker``."""
    folder.mkdir(parents=True)
    shutil.copy(PLANAR2 / "planar2.xml", folder / "planar2.xml")
    toml = (PLANAR2 / "robot.toml").read_text().replace('name = "planar2"', 'name = "evil"')
    (folder / "robot.toml").write_text(toml.replace("hooks.py:Planar2Arm", "hooks.py:Evil"))
    (folder / "hooks.py").write_text(
        f"from pathlib import Path\nPath({str(marker)!r}).write_text('ran')\nfrom sim_peer import ArmRobot as Evil\n"
    )
    return folder


def _unchanged(c: Class) -> None:
    """Both sims serve what they served, alice and bob keep their robots with their epochs, no hooks of hers ran."""
    assert c.parts() == {"sim-a": ["base0", "base2"], "sim-b": ["base1"]}, c.sims_output()[-2000:]
    assert c.sim_a.poll() is None and c.sim_b.poll() is None
    for who, rid, owner in ((c.alice, "base0", "alice"), (c.bob, "base1", "bob")):
        rec = who.ownership.record(rid)
        assert (rec.owner, rec.epoch) == (owner, c.epochs[rid]), rec
    assert not c.marker.exists()
    assert not re.search(r"handed \S+ out to|took \S+ in from", c.sims_output())


def _forged(
    c: Class,
    fab: Fabric,
    kind: str,
    rid: str,
    to: str,
    *,
    source_state: RobotState | None = None,
    rtype: str = "reeman",
    owner: str = "",
    pose=(0.0, 0.0, 0.0, 0.0),
    term: int = 100,
) -> Event:
    """The old protocol's hand-made step: a handoff carried in the query, which no sim accepts any more."""
    state = source_state or RobotState(rid, "mobile", np.array([pose[0], pose[1], pose[3]]), np.zeros(2), np.zeros(2))
    real = {r.object: r for ws in _states(fab, c.world) for r in ws.records}
    record = replace(real[rid], owner=owner or real[rid].owner, epoch=real[rid].epoch + 1) if rid in real else None
    h = ho.Handoff(state, SceneRobot(rtype, rid, pose), record, {}, {}, term, "sim-a")
    return ho.to_event(kind, rid, to, h, term=term, source=fab.peer_id)


def _states(fab: Fabric, world: str) -> list[WorldState]:
    """What srv/state tells any login: every robot's state and record (reading is everyone's)."""
    return [
        r.message for r in fab.rpc.query(keys.srv(world, "state"), timeout=5.0, expected=WorldState, all_replies=True)
    ]


def _attacks(c: Class, fab: Fabric) -> dict[str, Event]:
    states = {s.id: s for ws in _states(fab, c.world) for s in ws.robots}
    ahead = (1.5 - 0.9, 0.0, 0.0, 0.0)  # bob's base1 stands at x = 1.5 facing -x: 0.9 m before it
    return {
        "vanish": ho.to_event(ho.MOVE_OUT, "base1", "sim-nowhere", term=100, source=fab.peer_id),
        "steal": _forged(c, fab, ho.MOVE_IN, "base1", "sim-b", source_state=states["base1"], owner="mallory"),
        "clone": _forged(c, fab, ho.MOVE_IN, "base0", "sim-b", source_state=states["base0"]),
        "phantom": _forged(c, fab, ho.MOVE_IN, "ghost", "sim-b", pose=ahead),
        "kill a shard": _forged(c, fab, ho.MOVE_IN, "ghost2", "sim-b", rtype="no-such-robot"),
        "code execution": _forged(c, fab, ho.MOVE_IN, "evil1", "sim-b", rtype=str(c.evil), pose=ahead),
    }


def test_a_students_own_move_is_refused_with_the_reason_and_nothing_changes(cls):
    r = cls.cli("mallory", "own", "move", "base1", "--to", "sim-a")
    assert r.returncode == 1, r.stdout + r.stderr  # the world said no (docs/sim.md, docs/security.md)
    out = r.stdout + r.stderr
    assert "robot base1 not moved" in out and "instructor and sim logins" in out and "'mallory'" in out, out
    _unchanged(cls)


def test_a_students_hand_made_moves_on_srv_state_are_refused_counted_and_published(cls):
    mallory = cls.fabric("mallory", peer_id="mallory-tool")
    watcher = cls.fabric("viewer", "viewer", "watch-moves")
    refused: list[Event] = []
    watcher.subscribe(keys.event(cls.world, "move"), lambda key, ev: refused.append(ev), expected=Event)
    for name, ev in _attacks(cls, mallory).items():
        with pytest.raises(ServiceError) as err:
            mallory.rpc.query(keys.srv(cls.world, "state"), ev, timeout=5.0, all_replies=True)
        assert STAFF_ONLY in err.value.reason, (name, err.value.reason)
    wait_until(
        lambda: {e.data.get("step") for e in refused} >= {"move_out", "move_in"},
        timeout=20,
        what="the sims' move_refused events",
        seen=lambda: refused,
    )
    assert all(e.kind == "move_refused" and STAFF_ONLY in e.reason for e in refused), refused
    assert {e.header.source for e in refused} == {"sim-a", "sim-b"}  # each sim refuses and says so
    _unchanged(cls)


def test_a_student_may_not_ask_for_a_move_in_her_name_nor_in_the_instructors(cls):
    """srv/move/{sim}/by/{login}: the router lets no student ask there, in any name (it drops the query: no answer)."""
    mallory = cls.fabric("mallory", peer_id="mallory-tool2")
    for ev in _attacks(cls, mallory).values():  # each to sim-b: base1's sim, and every move_in's target
        for login in ("mallory", "carol"):
            with pytest.raises(ho.NoAnswer):
                ho.ask(mallory, "sim-b", login, ev, 1.0)
    for login in ("mallory", "carol"):
        wait_until(
            lambda: f"mallory query {keys.srv_move(cls.world, 'sim-b', login)}" in cls.procs.output(cls.router),
            timeout=20,
            what=f"the router's count of mallory's queries as {login}",
            seen=lambda: cls.procs.output(cls.router)[-1500:],
        )
    _unchanged(cls)


def test_the_sims_refuse_a_bad_move_even_from_the_instructor_and_keep_serving(cls):
    """What reaches srv/move is checked again: a move to a sim that is not there, a robot no source handed out in that
    move (phantom, clone), a type that is a path or not installed; a handed-out robot taken back by its source."""
    carol = cls.fabric("carol", "tool", "carol-tool")
    with pytest.raises(ho.MoveError, match="sim-nowhere is not another live sim"):
        ho.ask(carol, "sim-a", "carol", ho.step(ho.MOVE_OUT, "base2", to="sim-nowhere", term=100), 5.0)
    for rid in ("base0", "ghost"):  # a clone of a robot sim-a serves, a phantom: sim-a handed neither out
        with pytest.raises(ho.MoveError, match=f"no robot {rid} was handed out here"):
            ho.ask(
                carol,
                "sim-b",
                "carol",
                ho.step(ho.MOVE_IN, rid, to="sim-b", source="sim-a", term=100, move_id="x"),
                5.0,
            )
    for rtype, why in ((str(cls.evil), "is not a type name"), ("no-such-robot", "is not installed here")):
        with pytest.raises(ho.MoveError, match=why):
            ho.ask(
                carol,
                "sim-b",
                "carol",
                ho.step(ho.MOVE_PREPARE, "ghost", to="sim-b", source="sim-a", term=1, rtype=rtype),
                5.0,
            )
    _unchanged(cls)
    # a real hand-out, then a move_in naming another move: refused; the source takes it back as it kept it
    terms = {
        r.source: r.message.header.term
        for r in cls.probe.rpc.query(keys.srv(cls.world, "world"), expected=WorldInfo, all_replies=True)
    }
    term = ho.move_term(terms["sim-a"], terms["sim-b"])
    with pytest.raises(ho.MoveError, match="not the one the election gives"):
        ho.ask(carol, "sim-a", "carol", ho.step(ho.MOVE_OUT, "base2", to="sim-b", term=term + 50), 5.0)
    out = ho.ask(carol, "sim-a", "carol", ho.step(ho.MOVE_OUT, "base2", to="sim-b", term=term), 10.0)
    assert cls.parts() == {"sim-a": ["base0"], "sim-b": ["base1"]}
    with pytest.raises(ho.MoveError, match="handed out in another move"):
        ho.ask(
            carol,
            "sim-b",
            "carol",
            ho.step(ho.MOVE_IN, "base2", to="sim-b", source="sim-a", term=term, move_id="forged"),
            10.0,
        )
    ho.ask(
        carol,
        "sim-a",
        "carol",
        ho.step(ho.MOVE_IN, "base2", to="sim-a", source="sim-a", term=term, move_id=out.data["move"]),
        10.0,
    )
    assert "took base2" not in cls.procs.output(cls.sim_b)
    wait_until(
        lambda: cls.parts() == {"sim-a": ["base0", "base2"], "sim-b": ["base1"]}, timeout=20, what="base2 back at sim-a"
    )
    assert "took base2 in from sim-a" in cls.procs.output(cls.sim_a)  # its own, taken back
    for who, rid, owner in ((cls.alice, "base0", "alice"), (cls.bob, "base1", "bob")):
        assert (who.ownership.record(rid).owner, who.ownership.record(rid).epoch) == (owner, cls.epochs[rid])
    assert not cls.marker.exists() and cls.sim_a.poll() is None and cls.sim_b.poll() is None


def test_a_robot_no_target_fetched_is_served_by_its_source_again(cls):
    """The tool died between its two steps: the source serves the robot again after RETURN_AFTER_S, by itself."""
    carol = cls.fabric("carol", "tool", "carol-tool2")
    terms = {
        r.source: r.message.header.term
        for r in cls.probe.rpc.query(keys.srv(cls.world, "world"), expected=WorldInfo, all_replies=True)
    }
    ho.ask(
        carol,
        "sim-a",
        "carol",
        ho.step(ho.MOVE_OUT, "base2", to="sim-b", term=ho.move_term(terms["sim-a"], terms["sim-b"])),
        10.0,
    )
    assert cls.parts() == {"sim-a": ["base0"], "sim-b": ["base1"]}
    wait_until(
        lambda: cls.parts() == {"sim-a": ["base0", "base2"], "sim-b": ["base1"]},
        timeout=ho.RETURN_AFTER_S + 20,
        what="base2 served by sim-a again",
        seen=lambda: (cls.parts(), cls.procs.output(cls.sim_a)[-800:]),
    )
    said = f"no sim took base2 within {ho.RETURN_AFTER_S:.0f} s; serving it again"
    # the sim says so once it serves base2 again, so the line may come a moment after the world shows it
    wait_until(
        lambda: said in cls.procs.output(cls.sim_a),
        timeout=10,
        what="sim-a saying it serves base2 again",
        seen=lambda: cls.procs.output(cls.sim_a)[-800:],
    )
    assert cls.sim_b.poll() is None and "took base2" not in cls.procs.output(cls.sim_b)


def test_the_instructors_move_works_and_alice_and_bob_drive_on(cls):
    r = cls.cli("carol", "own", "move", "base2", "--to", "sim-b")
    assert r.returncode == 0, r.stdout + r.stderr
    assert "moved base2 from sim sim-a to sim sim-b" in r.stdout, r.stdout
    wait_until(
        lambda: cls.parts() == {"sim-a": ["base0"], "sim-b": ["base1", "base2"]},
        timeout=20,
        what="base2 at sim-b",
        seen=lambda: (cls.parts(), cls.sims_output()[-1500:]),
    )
    assert "asked by carol" in cls.procs.output(cls.sim_a) and "asked by carol" in cls.procs.output(cls.sim_b)
    for who, rid, owner in ((cls.alice, "base0", "alice"), (cls.bob, "base1", "bob")):
        rec = who.ownership.record(rid)
        assert (rec.owner, rec.epoch) == (owner, cls.epochs[rid]), rec
        base = who.robot(rid)
        x = base.xy_theta[0]
        base.twist(0.3, 0.0)
        try:
            wait_until(
                lambda: abs(base.xy_theta[0] - x) > 0.05,
                timeout=20,
                what=f"{owner} driving {rid}",
                seen=lambda: (base.xy_theta, who.events[-3:]),
            )
        finally:
            base.stop(timeout=10)
    assert not cls.marker.exists()
