"""A class world behind a real router started with `robofabric secure init`'s config.

The router, the sim peer (and, for Test A / Test B, the compute peer and the viewer) run as their
own processes with their own credentials; alice, bob and mallory log in as themselves. mallory
tries what a student could: forge alice's commands, ownership records and releases, publish robot
state and serve the world service. The router refuses what her login may not say; the sim and the
authority refuse what names someone other than its key's user.

"The router refused it" is shown by order: after each forgery mallory sends something she may
send on the same session; once that has arrived, the forgery would have arrived before it.
"""

from __future__ import annotations

import json
import math
import re
import subprocess
import threading
import time
import uuid
from dataclasses import replace

import numpy as np
import pytest

from fabric import keys
from fabric.codec import encode
from fabric.config import FabricConfig
from fabric.interfaces import (
    Command,
    Event,
    Header,
    JointState,
    JointTarget,
    OccupancyGrid,
    OwnershipRecord,
    OwnReply,
    OwnRequest,
    Stop,
    WorldInfo,
)
from robofabric.secure import init
from fabric.interfaces import ServiceError
from fabric.session import Fabric
from robofabric.testing import (
    ProcessGroup,
    SimRoles,
    client_config,
    free_port,
    robofabric_cmd,
    router_config,
    wait_until,
)

pytestmark = pytest.mark.slow


def _cli(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run(robofabric_cmd(*args), capture_output=True, text=True, timeout=timeout)


class SecureWorld:
    def __init__(self, tmp, procs: ProcessGroup) -> None:
        self.world = f"s{uuid.uuid4().hex[:8]}"
        self.port = free_port()
        self.ep = f"tcp/127.0.0.1:{self.port}"
        self.dir = tmp / "class"
        self.files = init(self.dir, users=["alice", "bob", "mallory"], instructors=["carol"], listen=[self.ep]).clients
        self.procs = procs
        self.router = procs.start(
            robofabric_cmd("router", "--zenoh-config", str(self.dir / "router.json5"), "--audit", "--audit-every", "1"),
            name="router",
        )
        wait_until(
            lambda: "listening" in procs.output(self.router),
            timeout=30,
            what="router",
            seen=lambda: procs.output(self.router),
        )
        self.fabrics: list[Fabric] = []

    def config(self, name: str) -> FabricConfig:
        return FabricConfig(world=self.world, config_file=str(self.files[name]))

    def fabric(self, name: str, kind: str = "user", peer_id: str | None = None) -> Fabric:
        fab = Fabric(self.config(name), kind=kind, peer_id=peer_id or name)
        self.fabrics.append(fab)
        return fab

    def start(self, name: str, *args: str):
        return self.procs.start(
            robofabric_cmd(*args, "--world", self.world, "--zenoh-config", str(self.files[name])), name=name
        )

    def close(self) -> None:
        for fab in self.fabrics:
            fab.close()


@pytest.fixture(scope="module")
def secure(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("secure")
    with ProcessGroup(tmp) as procs:
        w = SecureWorld(tmp, procs)
        sim = w.start("sim", "sim", "--scene", "combined")
        viewer = w.fabric("viewer", kind="viewer", peer_id="watcher")
        wait_until(
            lambda: viewer.live_peers("sim"), timeout=90, what="the sim peer", seen=lambda: procs.output(sim)[-2000:]
        )
        w.sim = sim
        w.sim_id = viewer.live_peers("sim")[0][1]  # the only sim yet: tests open probe sessions of kind sim later
        try:
            yield w
        finally:
            w.close()


class Seen:
    """Everything one subscription delivered, for assertions on what never arrived."""

    def __init__(self, fab: Fabric, key_expr: str, expected=None) -> None:
        self.items: list[tuple[str, object]] = []
        self.lock = threading.Lock()
        fab.subscribe(key_expr, self._on, expected=expected)

    def _on(self, key: str, msg: object) -> None:
        with self.lock:
            self.items.append((key, msg))

    def messages(self) -> list:
        with self.lock:
            return [m for _, m in self.items]


def _send(fab: Fabric, key: str, msg: object) -> None:
    """Put ``msg`` once a subscriber matches: a client drops a put nobody it knows of listens to, and a
    forgery that never left the client would prove nothing about the router."""
    pub = fab.session.declare_publisher(key)
    try:
        wait_until(lambda: pub.matching_status.matching, timeout=20, what=f"a subscriber for {key}")
        pub.put(encode(msg))
    finally:
        pub.undeclare()


def _marker(mallory: Fabric, seen_events: Seen, world: str, tag: str) -> None:
    """mallory sends what she may send (a decode report); once it arrived, everything before it did."""
    _send(mallory, keys.event_decode(world, "mallory"), Event(kind="marker", reason=tag, header=mallory.header("m")))
    wait_until(
        lambda: any(getattr(e, "reason", "") == tag for e in seen_events.messages()),
        timeout=20,
        what=f"mallory's marker {tag}",
    )


def _forged_header(real: Header) -> Header:
    """The header the real authority would put on its next message: its source and term, a fresh stamp."""
    return replace(real, wall_ns=time.time_ns(), seq=real.seq + 1)


def _refused_by_router(secure: SecureWorld, text: str) -> None:
    """The router's --audit summaries (robofabric/router_audit.py) name the refused login, message and key."""
    wait_until(
        lambda: text in secure.procs.output(secure.router),
        timeout=20,
        what=f"the router's count of {text!r}",
        seen=lambda: secure.procs.output(secure.router)[-1500:],
    )


@pytest.fixture(scope="module")
def alice_owns_arm(secure):
    import user_peer

    alice = user_peer.connect(world=secure.world, zenoh_config=str(secure.files["alice"]), timeout=10.0)
    arm = alice.robot("arm1")
    arm.wait_for("joints", timeout=30)
    arm.request(timeout=10)
    arm.move_joints([0.1] * 6, timeout=30)
    yield alice, arm
    alice.close()


def test_mallory_cannot_command_alices_arm(secure, alice_owns_arm):
    alice, arm = alice_owns_arm
    assert alice.user == "alice"  # the login is the user id
    w = secure.world
    watcher = secure.fabric("viewer", kind="viewer", peer_id="watch1")
    events, joints = Seen(watcher, keys.event_all(w), Event), Seen(watcher, keys.robot_joints(w, "arm1"), JointState)
    mallory = secure.fabric("mallory")
    epoch = alice.ownership.record("arm1").epoch
    bad = JointTarget(np.full(6, 0.5))
    _send(
        mallory, keys.robot_cmd(w, "arm1", "joints", "alice"), Command("alice", epoch, bad)
    )  # alice's key: the router refuses
    _send(
        mallory, keys.robot_cmd(w, "arm1", "joints", "mallory"), Command("alice", epoch, bad)
    )  # her key, alice's name
    ev = wait_until(
        lambda: [e for e in events.messages() if e.kind == "reject" and e.reason == "user_mismatch"],
        timeout=20,
        what="the sim refusing the payload's name",
        seen=events.messages,
    )[0]
    assert ev.user == "mallory" and ev.object == "arm1"
    # the forgery on alice's key went first on the same session: had the router passed it, the sim had it by now
    assert not [e for e in events.messages() if e.kind == "reject" and e.user == "alice"]
    n = len(joints.messages())
    wait_until(lambda: len(joints.messages()) > n + 20, timeout=20, what="joint states after the forgeries")
    assert all(np.allclose(js.q, 0.1, atol=1e-3) for js in joints.messages()[n:]), "the arm moved"
    # the router counted the refusal (robofabric router --audit), naming the login and the key
    refused = f"mallory put {keys.robot_cmd(w, 'arm1', 'joints', 'alice')}"
    wait_until(
        lambda: refused in secure.procs.output(secure.router),
        timeout=20,
        what="the router's count of the refusal",
        seen=lambda: secure.procs.output(secure.router)[-1500:],
    )


def test_a_fake_ownership_record_is_refused_and_alice_keeps_renewing(secure, alice_owns_arm):
    alice, arm = alice_owns_arm
    w = secure.world
    watcher = secure.fabric("viewer", kind="viewer", peer_id="watch2")
    events, records = Seen(watcher, keys.event_all(w), Event), Seen(watcher, keys.own_all(w), OwnershipRecord)
    mallory = secure.fabric("mallory")
    rec = alice.ownership.record("arm1")
    assert rec.header.term >= 1  # the clients' fence is up: a forgery must carry the term to get past it
    # plausible in every way a client can check: the authority's name, source and term, the next epoch;
    # only the router's access control stands between these and alice's client
    forged = OwnershipRecord(
        "arm1",
        owner="mallory",
        epoch=rec.epoch + 1,
        lease_expiry=rec.lease_expiry + 10.0,
        authority=rec.authority,
        header=_forged_header(rec.header),
    )
    _send(mallory, keys.own(w, "arm1"), forged)
    _send(mallory, keys.own(w, "arm1"), replace(forged, epoch=2**40, header=_forged_header(rec.header)))
    _marker(mallory, events, w, "after-records")
    assert not [r for r in records.messages() if r.owner == "mallory"]
    assert alice.ownership.record("arm1").owner == "alice"
    _refused_by_router(secure, f"mallory put {keys.own(w, 'arm1')}")
    # two lease periods (2 s each) later alice still owns it: she kept renewing
    first = watcher.rpc.call(keys.own(w, "arm1"), expected=OwnershipRecord)

    def renewed_past_two_leases() -> bool:
        later = watcher.rpc.call(keys.own(w, "arm1"), expected=OwnershipRecord)
        assert later.owner == "alice" and later.epoch == first.epoch, later  # hers all along, never taken over
        return later.lease_expiry > first.lease_expiry + 3.0  # a lease that ran out would move on no more

    wait_until(renewed_past_two_leases, timeout=20, interval=0.25, what="alice's renewals past two lease periods")


def test_mallory_cannot_release_alices_arm(secure, alice_owns_arm):
    alice, arm = alice_owns_arm
    w = secure.world
    mallory = secure.fabric("mallory")
    with pytest.raises(ServiceError, match="no reply"):  # alice's key: the router does not pass the query
        mallory.rpc.call(
            keys.own_request(w, "arm1", "alice"), OwnRequest("release", "alice"), timeout=2.0, expected=OwnReply
        )
    with pytest.raises(ServiceError, match="names 'alice' but was sent by 'mallory'"):
        mallory.rpc.call(
            keys.own_request(w, "arm1", "mallory"), OwnRequest("release", "alice"), timeout=10.0, expected=OwnReply
        )
    honest = mallory.rpc.call(
        keys.own_request(w, "arm1", "mallory"), OwnRequest("release", "mallory"), timeout=10.0, expected=OwnReply
    )
    assert honest.outcome != "released" and honest.record.owner == "alice"
    rec = mallory.rpc.call(keys.own(w, "arm1"), OwnRequest("release", "alice"), timeout=10.0, expected=OwnershipRecord)
    assert rec.owner == "alice"  # the record key only ever answers with the record
    assert alice.ownership.record("arm1").owner == "alice"


def test_only_the_instructor_may_ask_the_staffs_key(secure, alice_owns_arm):
    """mallory's staff action on arm1 is dropped by the router (and counted by its audit); carol, the instructor,
    is answered by the authority: her stop is done and alice keeps arm1."""
    alice, arm = alice_owns_arm
    w = secure.world
    mallory = secure.fabric("mallory")
    with pytest.raises(ServiceError, match="no reply"):
        mallory.rpc.call(
            keys.own_staff(w, "arm1", "mallory"), OwnRequest("take_back", "mallory"), timeout=2.0, expected=OwnReply
        )
    _refused_by_router(secure, f"mallory query {keys.own_staff(w, 'arm1', 'mallory')}")
    assert alice.ownership.record("arm1").owner == "alice"
    carol = secure.fabric("carol")
    reply = carol.rpc.call(
        keys.own_staff(w, "arm1", "carol"), OwnRequest("stop", "carol"), timeout=10.0, expected=OwnReply
    )
    assert reply.outcome == "done" and "arm1 stopped by instructor carol" in reply.reason
    assert reply.record.owner == "alice"


def test_a_user_cannot_publish_robot_state_or_serve_the_world(secure):
    w = secure.world
    watcher = secure.fabric("viewer", kind="viewer", peer_id="watch3")
    events, joints = Seen(watcher, keys.event_all(w), Event), Seen(watcher, keys.robot_joints(w, "arm1"), JointState)
    mallory = secure.fabric("mallory")
    # every forgery carries the sim's own source and term (read from its real messages), so that the
    # clients' fences would believe it: only the router's access control keeps it out
    real_js = wait_until(lambda: joints.messages(), timeout=20, what="a real joint state")[-1]
    real_world = mallory.rpc.call(keys.srv(w, "world"), timeout=10.0, expected=WorldInfo)
    real_rec = mallory.rpc.call(keys.own(w, "arm1"), timeout=10.0, expected=OwnershipRecord)
    assert real_js.header.term >= 1 and real_world.header.term >= 1 and real_rec.header.term >= 1
    marker_q = np.full(len(real_js.q), 1.2345)
    _send(mallory, keys.robot_joints(w, "arm1"), replace(real_js, q=marker_q, header=_forged_header(real_js.header)))
    mallory.rpc.serve(
        keys.srv(w, "world"),
        lambda key, req: replace(real_world, scene="mallory's", header=_forged_header(real_world.header)),
    )
    mallory.rpc.serve(
        keys.own(w, "arm1"),
        lambda key, req: replace(
            real_rec, owner="mallory", epoch=real_rec.epoch + 1, header=_forged_header(real_rec.header)
        ),
    )
    _marker(mallory, events, w, "after-state")
    assert not [js for js in joints.messages() if np.allclose(js.q, 1.2345)]
    answers = watcher.rpc.query(keys.srv(w, "world"), timeout=5.0, all_replies=True)
    assert answers and all(a.message.scene != "mallory's" for a in answers), answers
    records = watcher.rpc.query(keys.own(w, "arm1"), timeout=5.0, all_replies=True)
    assert records and all(r.message.owner != "mallory" for r in records)
    _refused_by_router(secure, f"mallory put {keys.robot_joints(w, 'arm1')}")
    # nor a compute's services: an IK "answer" of hers would steer whoever asks into her joints
    mallory.rpc.serve(keys.srv(w, "ik", "arm1"), lambda key, req: Event(kind="forged", reason="mallory's IK"))
    for key in (
        keys.srv(w, "world"),
        keys.own(w, "arm1"),
        keys.srv(w, "ik", "arm1"),
    ):  # her queryables: refused when declared
        _refused_by_router(secure, f"mallory declare_queryable {key} x")
    # her login, a sim's token: refused (and the queryable where it would tell its declarations, fabric.declared;
    # opened last: the audit's line names its five most refused, and the ones above are asserted by name)
    fake_sim = secure.fabric("mallory", kind="sim", peer_id="fake-sim")
    _refused_by_router(secure, f"mallory liveliness_token {keys.peer(w, 'sim', 'fake-sim')} x")  # her sim token
    assert ("sim", "fake-sim") not in watcher.live_peers("sim")
    assert fake_sim.peer_id == "fake-sim"


def test_a_newline_in_a_token_id_cannot_forge_a_line_of_the_routers_audit(secure):
    """mallory declares a sim's token (refused) whose id holds a newline and, after it, a line like the audit's own
    summary naming carol (not alice or bob: the paper test below reads the honest logins' refusals anywhere in the
    output): zenoh logs the key as it is. The audit shows her refusal on its own line with the newline escaped,
    and no line of the router's output starts with her text."""
    w = secure.world
    forged = f"refused in the last 1 s: 1 (put 1); carol put {keys.robot_cmd(w, 'base1', 'twist', 'bob')} x1"
    mallory = secure.fabric("mallory")
    token = mallory.session.liveliness().declare_token(f"{keys.peer(w, 'sim', 'x')}\n{forged}")
    try:
        _refused_by_router(secure, f"mallory liveliness_token {keys.peer(w, 'sim', 'x')}\\n{forged} x")
        out = secure.procs.output(secure.router)
        lines = [ln for ln in out.splitlines() if forged in ln]
        assert lines and all(
            not ln.startswith(forged) and ln.startswith(("refused in", "refused in total", "  ↳")) for ln in lines
        ), lines
        assert not [ln for ln in out.splitlines() if ln.startswith("refused in the last 1 s: 1 (put 1); carol put")]
    finally:
        token.undeclare()


def _router_admin_replies(fab: Fabric, selector: str = "@/*/router/**") -> list[str]:
    """Keys of the router's admin space (``@/ZID/router/**``: who subscribes to, serves and holds tokens on what)
    that answer ``fab``'s query; a session's own admin space (``@/ITS-ZID/session/**``) is not the router's."""
    return [str(r.ok.key_expr) for r in fab.session.get(selector, timeout=2.0) if r.ok is not None]


def test_a_student_cannot_read_the_routers_admin_space_nor_what_peers_subscribe_to(secure, tmp_path):
    """The router's admin space names every login's subscriptions, services and tokens, and zenoh ids; each peer tells
    its own subscriptions and services on its token's key (fabric.declared). In a class world (``secure init``) a
    student's query of either is answered by nobody, so ``list``/``ps -v`` show her no subscribers (docs/security.md);
    the instructor's is answered, by the class's sim among others. On an open LAN router the admin space's own entry
    answers anyone (the probe works; its other entries, which can stop a router, nobody asks: fabric/declared.py)."""
    from robofabric.declarations import read_declarations

    mallory = secure.fabric("mallory")
    assert _router_admin_replies(mallory) == []
    assert not read_declarations(mallory.session, secure.world, timeout=2.0).available
    carol = secure.fabric("carol", kind="tool", peer_id="carol-ps")
    told = wait_until(
        lambda: (d := read_declarations(carol.session, secure.world)).of_peer(secure.sim_id) and d,
        timeout=20,
        what="the class's sim telling the instructor what it serves",
    )
    assert (
        f"rf/{secure.world}/srv/world" in told.queryables
        and secure.sim_id in told.queryables[f"rf/{secure.world}/srv/world"]
    ), told
    world, port = f"o{uuid.uuid4().hex[:8]}", free_port()
    router = Fabric(router_config(world, port), kind="router", peer_id="router")
    try:
        anyone = Fabric(client_config(world, port), kind="user", peer_id="anyone")
        try:
            assert wait_until(
                lambda: _router_admin_replies(anyone, "@/*/router"),
                timeout=20,
                what="the open router's admin space answering",
            )
        finally:
            anyone.close()
    finally:
        router.close()


def test_a_sim_may_ask_its_router_whether_its_link_is_up_and_a_student_may_not(secure):
    """A standby that lost its leader's token asks its router (its admin space's own entry) whether its link is up
    before it takes over (sim_peer.replica.roles.router_answers): the class ACL lets sim logins ask that, and nothing
    else of the admin space; a student's question is answered by nobody."""
    from sim_peer.replica.roles import router_answers

    assert router_answers(secure.fabric("sim", kind="sim", peer_id="sim-probe"), 5.0)
    assert not router_answers(secure.fabric("mallory"), 1.0)


def test_a_sim_shows_its_role_through_the_class_acl(secure):
    """The class ACL lets a sim declare the token of its role (``peer/sim/{id}/{role}/{term}/{leader}``,
    sim_peer.replica.role_token): a viewer sees the class's only sim as its primary, under term 1."""
    watcher = secure.fabric("viewer", kind="viewer", peer_id="roles")
    roles = SimRoles(watcher)
    # the class's sim, not another test's probe session of kind sim (it shows no role: it is no sim peer)
    shown = wait_until(
        lambda: [(sim, r) for _, sim in watcher.live_peers("sim") if (r := roles.shows(sim, "primary", term=1))],
        timeout=30,
        what="a sim showing primary (term 1)",
        seen=lambda: [(sim, roles.now(sim)) for _, sim in watcher.live_peers("sim")],
    )
    assert [(sim, r.leader) for sim, r in shown] == [(secure.sim_id, secure.sim_id)], shown


@pytest.mark.parametrize("case", ["no credentials", "wrong password", "unknown user"])
def test_refused_logins_are_one_line_errors(secure, tmp_path, case):
    args = ["ps", "--world", secure.world]
    if case == "no credentials":
        args += ["--connect", secure.ep]
    else:
        cfg = json.loads("\n".join(secure.files["mallory"].read_text().splitlines()[2:]))
        if case == "wrong password":
            cfg["transport"]["auth"]["usrpwd"]["password"] = "guess"
        else:
            cfg["transport"]["auth"]["usrpwd"]["user"] = "eve"
        bad = tmp_path / "bad.json5"
        bad.write_text(json.dumps(cfg))
        args += ["--zenoh-config", str(bad)]
    out = _cli(*args)
    lines = out.stderr.strip().splitlines()
    assert out.returncode == 2 and len(lines) == 1 and "Traceback" not in out.stderr, out.stderr
    assert lines[0].startswith("error: authentication failed") and secure.ep in lines[0], lines
    who = {"no credentials": "at ", "wrong password": "for mallory at", "unknown user": "for eve at"}[case]
    assert who in lines[0]
    ok = _cli("ps", "--world", secure.world, "--zenoh-config", str(secure.files["bob"]))
    assert ok.returncode == 0, ok.stderr


def test_up_with_a_refused_login_says_so_in_one_line(secure, tmp_path):
    """``robofabric up`` joining the class router with a wrong password: the same line as every command
    (it said "cannot start the launch's router ... is another router using that port?")."""
    cfg = json.loads("\n".join(secure.files["mallory"].read_text().splitlines()[2:]))
    cfg["transport"]["auth"]["usrpwd"]["password"] = "guess"
    bad = tmp_path / "bad.json5"
    bad.write_text(json.dumps(cfg))
    launch = tmp_path / "up.toml"
    launch.write_text(
        f'[launch]\nworld = "{secure.world}"\nconnect = ["{secure.ep}"]\nzenoh_config = "{bad}"\n\n'
        '[[peer]]\nname = "ps"\nargs = ["ps"]\nrole = "task"\n'
    )
    out = _cli("up", str(launch), "--out", str(tmp_path / "out"))
    lines = out.stderr.strip().splitlines()
    assert out.returncode == 2 and len(lines) == 1 and "Traceback" not in out.stderr, out.stderr
    assert lines[0].startswith(
        f"error: authentication failed for mallory at {secure.ep}: the router refused this login"
    ), lines


def test_tls_refuses_a_certificate_from_another_ca(tmp_path):
    ep = f"tls/127.0.0.1:{free_port()}"
    mine = init(tmp_path / "mine", users=["alice"], tls=True, listen=[ep])
    other = init(tmp_path / "other", users=["alice"], tls=True, listen=[ep])
    with ProcessGroup(tmp_path) as procs:
        router = procs.start(robofabric_cmd("router", "--zenoh-config", str(mine.router)), name="router")
        wait_until(
            lambda: "listening" in procs.output(router),
            timeout=30,
            what="TLS router",
            seen=lambda: procs.output(router),
        )
        out = _cli("ps", "--zenoh-config", str(other.clients["alice"]))
        lines = out.stderr.strip().splitlines()
        assert out.returncode == 2 and len(lines) == 1 and "Traceback" not in out.stderr, out.stderr
        # her login trusts another CA: this side refuses the router first (the router would refuse her too)
        assert lines[0].startswith(
            f"error: cannot join world 'demo' at {ep}: this client does not trust the router's certificate ("
        ), lines
        good = _cli("ps", "--json", "--zenoh-config", str(mine.clients["alice"]))
        assert good.returncode == 0 and json.loads(good.stdout)["peers"].get("router"), good.stderr
        # identities by certificate common name: alice may not publish robot state even over TLS
        alice = Fabric(FabricConfig(config_file=str(mine.clients["alice"])), kind="user", peer_id="alice")
        sim = Fabric(FabricConfig(config_file=str(mine.clients["sim"])), kind="sim", peer_id="sim")
        try:
            got = Seen(sim, "rf/demo/**")

            def send() -> bool:  # again until the routes are up: the subscription is new
                alice.publish(keys.robot_joints("demo", "arm1"), JointState(["j"], np.zeros(1), np.zeros(1)))
                alice.publish(keys.robot_cmd("demo", "arm1", "stop", "alice"), Command("alice", 0, Stop()))
                return any("/cmd/stop/by/alice" in k for k, _ in got.items)

            wait_until(send, timeout=20, interval=0.2, what="alice's own command over TLS")
            assert not [k for k, _ in got.items if k.endswith("/joints")]
        finally:
            alice.close()
            sim.close()


def test_a_router_certificate_that_does_not_name_the_host_is_said_so(tmp_path):
    """The client refuses the router here, not the other way round: the message names the host (it said
    "the router refused this login"), for the CLI and as user_peer.JoinFailed with endpoint and cause."""
    import user_peer

    port = free_port()
    made = init(
        tmp_path / "class", users=["alice"], tls=True, listen=[f"tls/0.0.0.0:{port}"], connect=[f"tls/127.0.0.1:{port}"]
    )
    elsewhere = (
        f"tls/127.0.0.2:{port}"  # the router listens there too, but its certificate names 127.0.0.1 and localhost
    )
    with ProcessGroup(tmp_path) as procs:
        router = procs.start(robofabric_cmd("router", "--zenoh-config", str(made.router)), name="router")
        wait_until(
            lambda: "listening" in procs.output(router),
            timeout=30,
            what="TLS router",
            seen=lambda: procs.output(router),
        )
        assert _cli("ps", "--zenoh-config", str(made.clients["alice"])).returncode == 0
        out = _cli("ps", "--zenoh-config", str(made.clients["alice"]), "--connect", elsewhere)
        lines = out.stderr.strip().splitlines()
        assert out.returncode == 2 and len(lines) == 1 and "Traceback" not in out.stderr, out.stderr
        assert lines[0].startswith(
            f"error: cannot join world 'demo' at {elsewhere}: the router's certificate does not name 127.0.0.2 "
            "(it names "
        ), lines
        assert "refused this login" not in lines[0]
        with pytest.raises(user_peer.JoinFailed) as info:
            user_peer.connect(zenoh_config=str(made.clients["alice"]), connect=elsewhere, wait=False)
        assert info.value.endpoint == elsewhere and info.value.cause.startswith(
            "the router's certificate does not name 127.0.0.2"
        )
        assert info.traceback[-1].name == "connect"  # the script's own call is where it ends, no internal frames below


def _expire_certificate(d, name: str) -> None:
    """Replace ``name``'s certificate by one the class's own CA signed but that ran out yesterday."""
    import datetime as dt

    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization

    ca = x509.load_pem_x509_certificate((d / "ca.pem").read_bytes())
    ca_key = serialization.load_pem_private_key((d / "ca-key.pem").read_bytes(), password=None)
    key = serialization.load_pem_private_key((d / f"{name}-key.pem").read_bytes(), password=None)
    old = x509.load_pem_x509_certificate((d / f"{name}.pem").read_bytes())
    now = dt.datetime.now(dt.UTC)
    builder = (
        x509.CertificateBuilder()
        .subject_name(old.subject)
        .issuer_name(ca.subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - dt.timedelta(days=10))
        .not_valid_after(now - dt.timedelta(days=1))
    )
    for ext in old.extensions:
        builder = builder.add_extension(ext.value, critical=ext.critical)
    (d / f"{name}.pem").write_bytes(builder.sign(ca_key, hashes.SHA256()).public_bytes(serialization.Encoding.PEM))


def test_tls_refuses_an_expired_certificate(tmp_path):
    ep = f"tls/127.0.0.1:{free_port()}"
    made = init(tmp_path / "class", users=["alice", "bob"], tls=True, listen=[ep])
    from robofabric.secure import TLS_DIR

    _expire_certificate(tmp_path / "class" / TLS_DIR, "alice")
    with ProcessGroup(tmp_path) as procs:
        router = procs.start(robofabric_cmd("router", "--zenoh-config", str(made.router)), name="router")
        wait_until(
            lambda: "listening" in procs.output(router),
            timeout=30,
            what="TLS router",
            seen=lambda: procs.output(router),
        )
        good = _cli("ps", "--json", "--zenoh-config", str(made.clients["bob"]))  # the router is there for a valid one
        assert good.returncode == 0, good.stderr
        out = _cli("ps", "--zenoh-config", str(made.clients["alice"]))
        lines = out.stderr.strip().splitlines()
        assert out.returncode == 2 and len(lines) == 1 and "Traceback" not in out.stderr, out.stderr
        assert (
            lines[0] == f"error: authentication failed for alice at {ep}: the router refused this login "
            "(wrong password, unknown user, or a certificate it does not trust)"
        )


@pytest.fixture(scope="module")
def secure_compute(secure):
    """The class's compute peer under its own login (streaming IK for arm1, mapping and planning)."""
    compute = secure.start("compute", "compute", "--stream", "arm1:target")
    wait_until(
        lambda: "serving" in secure.procs.output(compute),
        timeout=90,
        what="the compute peer",
        seen=lambda: secure.procs.output(compute)[-1500:],
    )
    return compute


def test_forged_events_on_every_key_mallory_may_write_change_nothing(secure, alice_owns_arm):
    """mallory's Event(reject, arm1, alice) at 10 Hz on every event key she may write changes nothing: decode
    reports go on each writer's own key, clients act only on events from the object's authority on keys only sims
    write, so her forgeries are display-only; alice's moves and bob's drive go on."""
    import user_peer
    from fabric.interfaces import EventKind

    alice, arm = alice_owns_arm
    w = secure.world
    bob = user_peer.connect(world=w, zenoh_config=str(secure.files["bob"]), timeout=10.0)
    mallory = secure.fabric("mallory")
    stop = threading.Event()
    try:
        base = bob.robot("base1")
        base.wait_for("pose", timeout=30)
        base.request(timeout=10)
        sim_id = arm.record.authority  # the authority's own id: forgeries carry it as their source
        forged = [
            Event(
                kind=kind,
                object=obj,
                user=user,
                reason=f"{obj} is owned by mallory, not {user}",
                header=mallory.header("e"),
            )
            for obj, user in (("arm1", "alice"), ("base1", "bob"))
            for kind in (EventKind.REJECT, EventKind.OWN_REVOKED, EventKind.OWN_EXPIRED, EventKind.OWN_HANDOVER)
        ]
        forged = [replace(e, header=replace(e.header, source=sim_id, term=arm.record.header.term)) for e in forged]
        # every event key she may write (her own decode key), and those she may not (the router drops them)
        mine = keys.event_decode(w, "mallory")
        pubs = [
            mallory.session.declare_publisher(k)
            for k in (
                mine,
                keys.event_decode(w, "alice"),
                keys.event(w, "decode", "mallory"),
                keys.event(w, "reject", "arm1"),
                keys.event(w, "own", "base1"),
            )
        ]
        sent = []

        def flood() -> None:
            while not stop.is_set():
                for e in forged:
                    for pub in pubs:
                        pub.put(encode(e))
                sent.append(1)
                stop.wait(0.1)  # 10 Hz, twice the rate

        threading.Thread(target=flood, name="mallory-flood", daemon=True).start()
        forgery = lambda world: any("owned by mallory" in e.reason for e in list(world.events))  # noqa: E731
        wait_until(lambda: forgery(alice) and forgery(bob), timeout=20, what="her forgeries reaching alice and bob")
        for i in range(6):  # each would raise NotOwner had she believed a forgery
            arm.move_joints([0.1 + 0.05 * (i % 2)] * 6, timeout=30)
        start = base.xy_theta
        end = base.drive(0.3, 0.0, 2.0)  # a believed forgery would stop the base
        assert math.hypot(end[0] - start[0], end[1] - start[1]) > 0.2, (start, end)
        assert arm.record.owner == "alice" and base.record.owner == "bob"
        seen = [e for e in alice.events if e.kind == EventKind.REJECT and e.object == "arm1" and e.user == "alice"]
        assert seen, "her forged rejects never arrived: the test would prove nothing"
        assert not alice.rejections("arm1", 0) and not bob.rejections("base1", 0)
        assert all(
            not trusted for e, trusted in alice.recent_events(1000) if "owned by mallory" in e.reason
        )  # display-only
        assert alice.event_log.untrusted >= 8 and bob.event_log.untrusted >= 8
    finally:
        stop.set()
        for flooder in [t for t in threading.enumerate() if t.name == "mallory-flood"]:
            flooder.join(timeout=10)  # her last round is out before bob leaves
        bob.close()
    for key in (keys.event_decode(w, "alice"), keys.event(w, "decode", "mallory"), keys.event(w, "reject", "arm1")):
        _refused_by_router(secure, f"mallory put {key}")


def test_mallory_may_not_change_the_class_map_nor_plan_for_bobs_robot(secure, secure_compute):
    """mallory's map set (an all-occupied grid), reset (wiping the class's scans), stop (mapping off) and her
    plan for base1 (on robot/base1/path), asked in her name, are refused with the reason (the plan: hers is in the
    reply only); the staff's forms do not even reach the compute from her login."""
    import user_peer
    from fabric.interfaces import MapReply, MapRequest, Path, PlanReply, PlanRequest
    from user_peer import services

    w = secure.world
    mallory = secure.fabric("mallory")
    watcher = secure.fabric("viewer", kind="viewer", peer_id="watch-map")
    paths = Seen(watcher, keys.robot_path(w, "base1"), Path)
    maps = Seen(watcher, keys.map_key(w, "map"), None)
    bob = user_peer.connect(world=w, zenoh_config=str(secure.files["bob"]), timeout=10.0)
    try:
        base = bob.robot("base1")
        base.wait_for("pose", timeout=30)
        base.request(timeout=10)
        status = lambda: services.map_request(bob.fabric, "status", user="bob", timeout=10.0)  # noqa: E731
        before = wait_until(
            lambda: (lambda r: r if r.scans > 20 else None)(status()), timeout=60, what="scans in the class map"
        )
        full = OccupancyGrid(0.1, np.zeros(3), np.full((50, 50), 100, np.uint8))
        for req in (
            MapRequest("set", grid=full),
            MapRequest("reset"),
            MapRequest("stop"),
            MapRequest("save", file="x.yaml"),
        ):
            with pytest.raises(
                ServiceError,
                match=f"map '{req.action}' changes the map everyone plans on: an instructor's, not mallory's",
            ):
                mallory.rpc.call(keys.srv_asked(w, "map", "map", "mallory"), req, timeout=10.0, expected=MapReply)
            with pytest.raises(ServiceError, match="no reply"):  # the staff's form: her query never passes the router
                mallory.rpc.call(keys.srv(w, "map", "map"), req, timeout=2.0, expected=MapReply)
        after = status()
        assert after.mapping == 1 and after.scans >= before.scans, (before, after)  # on, and nothing wiped
        assert not maps.messages(), "a map was published"
        _refused_by_router(secure, f"mallory query {keys.srv(w, 'map', 'map')}")
        # an instructor may: a free room of her own, for the plans below (the class map stays as it is)
        carol = secure.fabric("carol")
        room = OccupancyGrid(0.1, np.array([-5.0, -5.0, 0.0]), np.zeros((100, 100), np.uint8))
        assert (
            carol.rpc.call(
                keys.srv(w, "map", "room"), MapRequest("set", name="room", grid=room), timeout=10.0, expected=MapReply
            ).action
            == "set"
        )
        plan = PlanRequest(
            "base1", goal=np.array([2.0, 1.0, 0.0]), start=np.array([0.0, 0.0, 0.0]), map="room", direction="both"
        )
        theirs = mallory.rpc.call(keys.srv_asked(w, "plan", "base1", "mallory"), plan, timeout=30.0, expected=PlanReply)
        assert len(theirs.path) > 1  # she gets her path, in the reply
        with pytest.raises(ServiceError, match="no reply"):
            mallory.rpc.call(keys.srv(w, "plan", "base1"), plan, timeout=2.0, expected=PlanReply)
        own = bob.fabric.rpc.call(
            keys.srv_asked(w, "plan", "base1", "bob"),
            replace(plan, goal=np.array([1.5, -1.0, 0.0])),
            timeout=30.0,
            expected=PlanReply,
        )
        got = wait_until(lambda: paths.messages(), timeout=20, what="bob's plan on robot/base1/path")
        # hers was asked (and answered) first: published, it would have come first on the same path key
        assert len(got) == 1 and np.allclose(got[0].y, own.path.y), [p.y[-1] for p in got]
    finally:
        bob.close()


def test_paper_tests_a_and_b_in_a_secure_world(secure, alice_owns_arm, secure_compute):
    """Router, sim, compute and viewer with their own logins; alice runs Test A, bob Test B (trimmed)."""
    import user_peer
    from user_peer.scenarios import test_a, test_b

    alice, arm = alice_owns_arm
    arm.release()
    procs = secure.procs
    compute = secure_compute
    rrd = secure.dir.parent / "secure.rrd"
    viewer = secure.start("viewer", "view", "--save", str(rrd))
    watcher = secure.fabric("viewer", kind="viewer", peer_id="watch4")
    # the compute peer's token comes before its services: its "serving" line says they are declared
    wait_until(
        lambda: "serving" in procs.output(compute) and watcher.live_peers("viewer"),
        timeout=90,
        what="compute and viewer",
        seen=lambda: (procs.output(compute)[-1500:], procs.output(viewer)[-1500:]),
    )
    bob = user_peer.connect(world=secure.world, zenoh_config=str(secure.files["bob"]), timeout=10.0)
    results = {}
    try:
        tb = threading.Thread(target=lambda: results.setdefault("b", test_b(bob, tol=0.35)), daemon=True)
        ta = threading.Thread(target=lambda: results.setdefault("a", test_a(alice, points=3)), daemon=True)
        ta.start()
        tb.start()
        ta.join(240)
        tb.join(240)
    finally:
        bob.close()
    a, b = results.get("a"), results.get("b")
    assert a is not None and a.ok, a and a.lines
    assert b is not None and b.ok, b and b.lines
    assert a.user == "alice" and b.user == "bob"
    assert any("took arm1 over where it was" in line for line in b.lines), b.lines
    assert compute.poll() is None and viewer.poll() is None
    assert math.isfinite(b.figures["goal_error_m"])
    # a late joiner gets the latched values (scene objects, the map) from their writers' caches
    late = secure.fabric("viewer", kind="viewer", peer_id="late")
    got: dict[str, object] = {}
    late.subscribe(keys.object_pose_all(secure.world), lambda k, m: got.setdefault(k, m), history=True)
    bobs_map = keys.map_key(secure.world, keys.user_map("map", "bob"))  # Test B builds and plans on bob's own map
    late.subscribe(bobs_map, lambda k, m: got.setdefault(k, m), history=True)
    wait_until(
        lambda: keys.object_pose(secure.world, "target", "alice") in got and bobs_map in got,
        timeout=20,
        what="latched values for a late joiner",
        seen=lambda: sorted(got),
    )
    # and the router refused nothing of what the honest logins said (its --audit summaries name every refusal):
    # a refusal after all of theirs (mallory's put on a sim's key) is counted in the same summary or a later one
    before = len(procs.output(secure.router))
    canary = keys.robot_joints(secure.world, "arm1")
    secure.fabric("mallory", peer_id="mallory4").session.put(canary, b"canary")
    wait_until(
        lambda: f"mallory put {canary}" in procs.output(secure.router)[before:],
        timeout=20,
        what="the router's count of a refusal after the scenarios",
        seen=lambda: procs.output(secure.router)[-1500:],
    )
    honest = re.findall(r"\b(alice|bob|sim|compute|viewer) (\w+) (rf/\S+) x\d+", procs.output(secure.router))
    assert not honest, honest


def test_the_python_api_says_who_was_refused_and_keeps_the_login_as_the_user(secure, tmp_path):
    import user_peer
    from fabric.config import ConfigError
    from user_peer.errors import Unreachable

    cfg = json.loads("\n".join(secure.files["bob"].read_text().splitlines()[2:]))
    cfg["transport"]["auth"]["usrpwd"]["password"] = "guess"
    bad = tmp_path / "bob-bad.json5"
    bad.write_text(json.dumps(cfg))
    with pytest.raises(
        Unreachable, match=f"^authentication failed for bob at {secure.ep}: the router refused this login"
    ) as info:
        user_peer.connect(world=secure.world, zenoh_config=str(bad), wait=False)
    assert isinstance(info.value, user_peer.JoinFailed) and info.value.endpoint == secure.ep  # one type, where and why
    assert info.value.cause.startswith("the router refused this login")
    with pytest.raises(ConfigError, match="logs in as 'bob'.*not 'alice'"):
        user_peer.connect(world=secure.world, zenoh_config=str(secure.files["bob"]), user="alice", wait=False)
