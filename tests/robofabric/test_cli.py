"""The robofabric CLI against live processes: router, pub, echo, hz, ps, and user mistakes."""

import json
import subprocess

import pytest

from fabric import keys
from robofabric import cli
from robofabric.testing import free_port, robofabric_cmd, wait_until

pytestmark = pytest.mark.slow  # every test here starts processes or runs for seconds


def run_cli(*args, timeout=60):
    return subprocess.run(robofabric_cmd(*args), capture_output=True, text=True, timeout=timeout)


@pytest.fixture
def cli_router(procs, world):
    """A `robofabric router` in its own process; yields its endpoint."""
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    proc = procs.start(robofabric_cmd("router", "--listen", ep, "--world", world), name="router")
    wait_until(
        lambda: "listening" in procs.output(proc), timeout=60, what="router to listen", seen=lambda: procs.output(proc)
    )
    return ep


def test_two_processes_talk_through_the_router(cli_router, world, procs):
    key = keys.robot_cmd(world, "base1", "twist", "alice")
    echo = procs.start(
        robofabric_cmd(
            "echo", "robot/*/cmd/*/by/*", "--json", "--count", "3", "--world", world, "--connect", cli_router
        ),
        name="echo",
    )
    wait_until(lambda: _live(world, cli_router, "tool"), timeout=20, what="echo to join")
    pub = procs.start(
        robofabric_cmd(
            "pub",
            "robot/base1/cmd/twist",
            "-t",
            "Twist",
            "-d",
            '{"v": 0.3, "omega": -0.1}',
            "--user",
            "alice",
            "--epoch",
            "4",
            "--rate",
            "20",
            "--world",
            world,
            "--connect",
            cli_router,
        ),
        name="pub",
    )
    echo.wait(timeout=30)
    lines = [json.loads(line) for line in procs.output(echo).splitlines() if line.startswith("{")]
    assert len(lines) == 3 and echo.returncode == 0
    assert all(line["key"] == key for line in lines)
    msg = lines[0]["message"]
    assert msg["type"] == "Command" and msg["user"] == "alice" and msg["epoch"] == 4
    assert msg["body"]["type"] == "Twist" and msg["body"]["v"] == 0.3
    procs.kill(pub)


def _live(world, ep, kind):
    out = run_cli("ps", "--json", "--world", world, "--connect", ep)
    return out.returncode == 0 and json.loads(out.stdout)["peers"].get(kind)


def test_ps_and_hz_see_a_live_publisher(cli_router, world, procs):
    pub = procs.start(
        robofabric_cmd(
            "pub",
            "robot/arm1/cmd/stop/by/ann",
            "-t",
            "Stop",
            "--rate",
            "50",
            "--world",
            world,
            "--connect",
            cli_router,
            "--id",
            "stopper",
        ),
        name="pub",
    )
    wait_until(lambda: "stopper" in (_live(world, cli_router, "tool") or []), timeout=60, what="publisher in ps")
    out = run_cli(
        "hz", "robot/arm1/cmd/stop/by/ann", "--duration", "3", "--json", "--world", world, "--connect", cli_router
    )
    assert out.returncode == 0, out.stderr
    stream = json.loads(out.stdout)["streams"][keys.robot_cmd(world, "arm1", "stop", "ann")]
    assert 30 < stream["rate_hz"] < 70, stream
    assert stream["bytes_per_s"] > 0 and stream["count"] > 50
    table = run_cli("ps", "--world", world, "--connect", cli_router)
    assert "stopper" in table.stdout and "tool" in table.stdout
    procs.kill(pub)


def test_echo_reports_garbage_and_keeps_going(cli_router, world, procs, router):
    echo = procs.start(
        robofabric_cmd(
            "echo", "robot/arm1/joints", "--json", "--count", "1", "--world", world, "--connect", cli_router
        ),
        name="echo",
    )
    from fabric.config import FabricConfig
    from fabric.interfaces import JointState
    from fabric.session import Fabric

    with Fabric(FabricConfig(world=world, connect=(cli_router,)), kind="sim", peer_id="sim1") as sim:
        key = keys.robot_joints(world, "arm1")

        def poke():
            sim.put_raw(key, b"\xc1\xc1 not msgpack")
            sim.publish(key, JointState(["a"], [0.25], [0.0]))
            return echo.poll() is not None

        wait_until(poke, timeout=30, interval=0.2, what="echo to print one valid message")
    out = procs.output(echo)
    assert "bad payload" in out
    assert json.loads([line for line in out.splitlines() if line.startswith("{")][0])["message"]["q"] == [0.25]


@pytest.mark.parametrize(
    "args,needle",
    [
        (
            ("echo", "rf/demo/**/$#bad", "--connect", "tcp/127.0.0.1:1", "--duration", "0.1"),
            "not a valid key expression",
        ),
        (("ps", "--connect", "192.168.1.1"), "is not of the form PROTO/ADDRESS:PORT"),
        (("ps", "--world", "a/b"), "world 'a/b' contains forbidden"),
        (("pub", "robot/a/cmd/twist", "-t", "Warp"), "unknown message type 'Warp'"),
        (("pub", "robot/a/cmd/twist", "-t", "Twist", "-d", '{"v": "fast"}'), "Twist needs field 'omega' (a number)"),
        (("up", "/nonexistent/launch.toml"), "no such launch file"),
        (("bench", "transport", "--rates", "x"), "--rates"),
    ],
)
def test_user_mistakes_give_one_line_and_exit_2(args, needle):
    out = run_cli(*args)
    assert out.returncode == 2, (out.stdout, out.stderr)
    assert needle in out.stderr
    assert "Traceback" not in out.stderr


def test_every_command_has_help(capsys):
    """The list from a real process, each command's help in this one (a process each cost eight CLI starts)."""
    out = run_cli("--help")
    assert out.returncode == 0
    for cmd in ("router", "ps", "echo", "hz", "pub", "up", "demo", "bench"):
        assert cmd in out.stdout
        assert cli.main([cmd, "--help"]) == 0, (cmd, capsys.readouterr().err)
        assert "Usage" in capsys.readouterr().out, cmd


def test_echo_timeout_on_a_silent_key_exits_1_saying_so(router, world):
    ep = f"tcp/127.0.0.1:{router[1]}"
    out = run_cli("echo", "robot/arm9/joints", "--timeout", "0.5", "--world", world, "--connect", ep)
    assert out.returncode == 1 and f"nothing on rf/{world}/robot/arm9/joints in 0.5 s" in out.stderr, (
        out.stdout + out.stderr
    )
