"""Real zenoh sessions on loopback: pub/sub, bad payloads, services, liveliness."""

import json
import time

import pytest
import zenoh

from fabric import keys
from fabric.config import ConfigError, FabricConfig
from fabric.interfaces import Event, JointState, Stop, Twist
from fabric.interfaces import ServiceError
from robofabric.testing import robofabric_cmd, wait_until


def test_publish_subscribe_with_headers(world, connect):
    sim, user = connect("sim", "sim1"), connect("user", "alice")
    got = []
    user.subscribe(keys.robot_all(world), lambda k, m: got.append((k, m)))
    key = keys.robot_joints(world, "arm1")

    def send():
        sim.publish(key, JointState(["j1"], [0.5], [0.0], header=sim.header(key, stamp=1.0)))
        return len(got) > 0

    wait_until(send, timeout=10, what="first joint state to arrive", seen=lambda: got)
    k, msg = got[0]
    assert k == key and msg.q.tolist() == [0.5]
    assert msg.header.source == "sim1" and msg.header.wall_ns > 0


def test_bad_payload_is_counted_reported_and_subscriber_keeps_working(world, connect):
    sim, user = connect("sim", "sim1"), connect("user", "bob")
    got, events = [], []
    key = keys.robot_joints(world, "arm1")
    user.subscribe(key, lambda k, m: got.append(m))
    sim.subscribe(keys.event_all(world), lambda k, m: events.append((k, m)))
    wait_until(lambda: (sim.put_raw(key, b"\x93garbage"), user.counters["decode_errors"] > 0)[1], what="decode error")
    wait_until(lambda: events, what="decode event", seen=lambda: events)
    k, ev = events[0]
    assert k == keys.event_decode(world, "bob")  # its own key: a router lets each login write only its own
    assert ev.kind == "decode_error" and ev.data["key"] == key and "not a msgpack message" in ev.reason
    wait_until(
        lambda: (sim.publish(key, JointState(["a"], [1.0], [0.0])), got)[1], what="valid message after a bad one"
    )


def test_service_replies_and_refusals(world, connect):
    server, caller = connect("compute", "c1"), connect("user", "u1")

    def handler(key, request):
        if request is None:
            raise ServiceError("a Twist request is required")
        return Twist(request.v * 2, request.omega, header=server.header(key))

    key = keys.srv(world, "fk", "arm1")
    server.rpc.serve(key, handler, expected=Twist)
    reply = wait_until(lambda: _try(lambda: caller.rpc.call(key, Twist(1.5, 0.0))), what="service reply")
    assert reply.v == 3.0 and reply.header.source == "c1"
    with pytest.raises(ServiceError, match="a Twist request is required"):
        caller.rpc.call(key)
    with pytest.raises(ServiceError, match="expected Twist, got Stop"):
        caller.rpc.call(key, Stop())
    with pytest.raises(ServiceError, match="no reply"):
        caller.rpc.call(keys.srv(world, "ik", "nobody"), timeout=0.3)


def _try(fn):
    try:
        return fn()
    except ServiceError:
        return None


def test_all_replies_reaches_every_server(world, connect):
    a, b, caller = connect("compute", "ca"), connect("compute", "cb"), connect("user", "u")
    key = keys.srv(world, "plan", "base1")
    for fab in (a, b):
        fab.rpc.serve(key, lambda k, r, fab=fab: Event(kind="pong", reason=fab.peer_id, header=fab.header(k)))
    wait_until(
        lambda: len(_try(lambda: caller.rpc.query(key, all_replies=True, timeout=0.5)) or []) == 2, what="two replies"
    )
    sources = sorted(r.message.reason for r in caller.rpc.query(key, all_replies=True))
    assert sources == ["ca", "cb"]


@pytest.mark.slow
def test_liveliness_tracks_a_process_that_exits_and_one_that_is_killed(world, router, connect, procs):
    port = router[1]
    seen = {}
    watcher = connect("tool", "watcher")
    watcher.watch_peers(lambda kind, pid, alive: seen.__setitem__(pid, alive))
    argv = robofabric_cmd("echo", "robot/**", "--world", world, "--connect", f"tcp/127.0.0.1:{port}")
    p_exit = procs.start(argv, name="echo1")
    # a child's start (its imports) is not what is judged: at load 37 it took over 10 s
    wait_until(
        lambda: any(v for k, v in seen.items() if k.startswith("tool-")),
        timeout=60,
        what="echo peer token",
        seen=lambda: seen,
    )
    first = next(k for k, v in seen.items() if v and k.startswith("tool-"))
    procs.kill(p_exit, sig=15)  # SIGTERM: clean exit
    assert p_exit.returncode == 0, procs.output(p_exit)
    wait_until(lambda: seen.get(first) is False, timeout=5, what="token gone after exit", seen=lambda: seen)
    p_kill = procs.start(argv, name="echo2")
    wait_until(
        lambda: any(v for k, v in seen.items() if k.startswith("tool-") and k != first),
        timeout=60,
        what="second token",
        seen=lambda: seen,
    )
    second = next(k for k, v in seen.items() if v and k.startswith("tool-") and k != first)
    procs.kill(p_kill)  # SIGKILL: the OS closes the socket
    wait_until(lambda: seen.get(second) is False, timeout=5, what="token gone after SIGKILL", seen=lambda: seen)


def test_config_profiles_and_env():
    cfg = FabricConfig.resolve(
        env={"ROBOFABRIC_CONNECT": "tcp/10.0.0.5:7447, tcp/10.0.0.6:7447", "ROBOFABRIC_WORLD": "lab"}
    )
    assert cfg.world == "lab" and cfg.connect == ("tcp/10.0.0.5:7447", "tcp/10.0.0.6:7447")
    assert FabricConfig.resolve(
        world="w", connect=["tcp/1.2.3.4:1"], env={"ROBOFABRIC_CONNECT": "tcp/9.9.9.9:9"}
    ).connect == ("tcp/1.2.3.4:1",)
    assert FabricConfig(profile="embedded").endpoints() == ((), ("tcp/127.0.0.1:7447",))
    assert FabricConfig().endpoints() == (("tcp/127.0.0.1:7447",), ())
    conf = json.loads(str(FabricConfig(profile="peer").zenoh_config().get_json("scouting/multicast/enabled")))
    assert conf is True
    for bad in (dict(profile="cloud"), dict(world="a/b"), dict(connect=("192.168.1.1",)), dict(lease_ms=5)):
        with pytest.raises((ConfigError, ValueError)):
            FabricConfig(**bad)


def test_sessions_cap_message_size_and_an_oversized_message_is_dropped_not_the_link(world, connect):
    from fabric.config import MAX_MESSAGE_SIZE

    conf = FabricConfig(profile="client").zenoh_config()
    assert json.loads(conf.get_json("transport/link/rx/max_message_size")) == MAX_MESSAGE_SIZE
    sender, receiver = connect("tool", "big"), connect("tool", "rx")
    got = []
    key = keys.robot_joints(world, "arm1")
    receiver.subscribe_raw(key, lambda s: got.append(len(s.payload.to_bytes())))
    wait_until(lambda: (sender.put_raw(key, b"warm"), got)[1], what="link up")
    sender.put_raw(key, b"x" * (3 * MAX_MESSAGE_SIZE))
    wait_until(
        lambda: (sender.put_raw(key, b"after"), 5 in got)[1],
        timeout=30,
        what="a message after the oversized one",
        seen=lambda: got,
    )
    assert 3 * MAX_MESSAGE_SIZE not in got


def test_a_flood_of_bad_payloads_is_counted_in_full_and_reported_a_few_times(world, connect):
    from fabric.reports import REPORT_BURST

    sender, receiver = connect("tool", "junk"), connect("user", "carol")
    events = []
    key = keys.robot_joints(world, "arm1")
    receiver.subscribe(keys.robot_stream_all(world, "joints"), lambda k, m: None)
    sender.subscribe(keys.event_all(world), lambda k, m: events.append(m), expected=Event)
    wait_until(
        lambda: (sender.put_raw(key, b"\x93junk"), receiver.counters["decode_errors"])[1], what="first decode error"
    )
    for i in range(500):  # a new robot id each time: still one subscription, one report key
        # BLOCK: zenoh drops none of them on the way, so every one must be counted
        sender.session.put(
            keys.robot_joints(world, f"r{i}"), b"\x93junk" * 1000, congestion_control=zenoh.CongestionControl.BLOCK
        )
    wait_until(
        lambda: receiver.counters["decode_errors"] >= 501,
        what="every bad payload counted",
        seen=lambda: receiver.counters,
    )
    wait_until(lambda: events, what="a decode event")
    assert len(events) <= REPORT_BURST
    assert receiver.counters["reports_suppressed"] >= 501 - REPORT_BURST
    assert all(len(e.reason) <= 240 and len(e.data["key"]) <= 240 for e in events)
    assert len(receiver.published_keys) <= 2  # the event key, nothing per robot id


def test_a_server_that_answers_too_late_is_no_reply_not_a_refusal(world, connect):
    """zenoh ends such a query with an error reply of its own ("Timeout"); read as a refusal, it made
    a user's join fail at once ("refused its description: Timeout") instead of waiting for the sim."""
    from fabric.interfaces import NoReply, Refused

    server, caller = connect("sim", "s1"), connect("user", "u1")

    def handler(key, request):
        if request is not None:  # the real call: answers after the caller's limit
            time.sleep(1.0)
        return Twist(1.0, 0.0)

    key = keys.srv(world, "world")
    server.rpc.serve(key, handler)
    wait_until(lambda: _try(lambda: caller.rpc.call(key, timeout=1.0)), what="the server answering a probe")
    with pytest.raises(NoReply, match="no server answered in time") as err:
        caller.rpc.call(key, Stop(), timeout=0.3)
    assert not isinstance(err.value, Refused)


def test_client_sessions_reconnect_within_a_second_unless_their_file_says_otherwise(tmp_path):
    """Every client and peer retries its router at most a second apart (zenoh backs off to 4 s), so after a router's
    restart the peers come back together; a router does not dial, and a zenoh file's own ``connect/retry`` stays."""
    import json as _json

    from fabric.config import RECONNECT_RETRY, FabricConfig

    client = FabricConfig(world="w", profile="client", connect=("tcp/127.0.0.1:7447",))
    assert _json.loads(client.zenoh_config().get_json("connect/retry")) == RECONNECT_RETRY
    mine = tmp_path / "z.json5"
    mine.write_text("{connect: {retry: {period_init_ms: 2000, period_max_ms: 8000, period_increase_factor: 2}}}")
    own = FabricConfig(world="w", profile="client", connect=("tcp/127.0.0.1:7447",), config_file=str(mine))
    assert _json.loads(own.zenoh_config().get_json("connect/retry"))["period_max_ms"] == 8000
    router = FabricConfig(world="w", profile="embedded")
    assert _json.loads(router.zenoh_config().get_json("connect/retry")) != RECONNECT_RETRY
