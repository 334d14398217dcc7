"""One exit-code rule for every command, and streaming commands that end cleanly.

0: what was asked happened (a streaming command whose reader went away, ``| head -3``, or that was
stopped with Ctrl-C, did what it was asked); 1: the world answered no or had nothing; 2: a usage
error or a router that cannot be reached. Never a traceback.
"""

from __future__ import annotations

import os
import signal
import subprocess
import threading

import numpy as np
import pytest

from fabric import keys
from robofabric.cli import main
from fabric.interfaces import Header, JointState
from robofabric.testing import free_port, robofabric_cmd, wait_until


def test_the_rule_is_in_robofabric_help(capsys):
    assert main(["--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "0 what was asked happened" in text and "1 the world answered no or had nothing" in text
    assert "2 a usage error or a router that cannot be reached" in text


def _cli(*args: str, timeout: float = 90) -> subprocess.CompletedProcess:
    return subprocess.run(robofabric_cmd(*args), capture_output=True, text=True, timeout=timeout)


@pytest.fixture
def joints_world(router, connect, world):
    """An arm's joints at ~100 Hz until the test ends; yields the router's endpoint."""
    pub = connect("tool", peer_id="sim-test")
    stop = threading.Event()

    def run() -> None:
        i = 0
        while not stop.wait(0.01):
            pub.publish(
                keys.robot_joints(world, "arm1"),
                JointState(("j1",), np.zeros(1), np.zeros(1), Header.now(seq=i, source="sim-test")),
            )
            i += 1

    t = threading.Thread(target=run, daemon=True)
    t.start()
    yield f"tcp/127.0.0.1:{router[1]}"
    stop.set()
    t.join(timeout=5)


def _head(procs, argv: list[str], lines: int) -> tuple[int, str]:
    """Run ``argv | head -LINES``: read that many lines, close the pipe; (exit code, stderr)."""
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    procs.procs.append(proc)  # ended by pid at teardown if it hangs
    got = [proc.stdout.readline() for _ in range(lines)]
    assert all(got), got
    proc.stdout.close()
    rc = proc.wait(timeout=60)  # it must notice the closed pipe and end by itself
    return rc, proc.stderr.read().decode(errors="replace")


@pytest.mark.slow
@pytest.mark.parametrize("cmd", [("echo", "robot/**", "--json"), ("echo", "robot/arm1/joints"), ("hz", "robot/**")])
def test_a_streaming_command_ends_with_0_when_its_reader_goes(joints_world, world, procs, cmd):
    rc, err = _head(procs, robofabric_cmd(*cmd, "--world", world, "--connect", joints_world), 3)
    assert rc == 0 and "Traceback" not in err and "BrokenPipe" not in err, (rc, err)


def _interrupt(procs, argv: list[str], ready: str) -> tuple[int, str]:
    proc = procs.start(argv, name=argv[3])
    wait_until(
        lambda: ready in procs.output(proc),
        timeout=60,
        what=f"{ready!r} printed",
        seen=lambda: procs.output(proc)[-2000:],
    )
    os.kill(proc.pid, signal.SIGINT)
    return proc.wait(timeout=60), procs.output(proc)


@pytest.mark.slow
def test_ctrl_c_ends_streaming_commands_with_0_and_no_traceback(joints_world, world, procs, tmp_path):
    common = ("--world", world, "--connect", joints_world)
    for argv, ready in (
        (robofabric_cmd("echo", "robot/**", "--json", *common), '"key"'),
        (robofabric_cmd("hz", "robot/**", *common), "Hz"),
        # a recorder's first progress line (after 5 s): it has recorded something, so it did what was asked
        (robofabric_cmd("record", "-o", str(tmp_path / "r.mcap"), *common), " msgs "),
        (robofabric_cmd("record", "-o", str(tmp_path / "r2.mcap"), "--to", "ros2", *common), " msgs "),
    ):
        rc, out = _interrupt(procs, argv, ready)
        assert rc == 0 and "Traceback" not in out, (argv[3:5], rc, out[-2000:])


@pytest.mark.slow
def test_nothing_there_exits_1(router, world):
    ep = ("--world", world, "--connect", f"tcp/127.0.0.1:{router[1]}")
    for args, says in (
        (("info", "robot/nope/joints", "--duration", "1"), "nothing publishes or serves"),
        (("info", "robot/nope/joints", "--duration", "1", "--json"), "no message on"),
        (("hz", "robot/**", "--duration", "1"), "no messages on"),
        (("call", "srv/nope", "--timeout", "1"), "no reply on"),
        (("own", "list"), "no ownership authority answered"),
        (("own", "request", "arm1", "--user", "ann"), "request arm1: no reply"),
        (("list", "--duration", "1"), "nothing published on"),
        (("echo", "robot/**", "--timeout", "1"), "nothing on"),
        (("echo", "robot/**", "--duration", "1"), "nothing on"),
        (("own", "move", "base1", "--to", "sim-b"), "robot base1 not moved: no sim describes world"),
    ):
        out = _cli(*args, *ep)
        assert out.returncode == 1 and says in out.stderr and "Traceback" not in out.stderr, (
            args,
            out.returncode,
            out.stderr,
        )


@pytest.mark.slow
def test_an_unreachable_router_exits_2_in_robofabrics_words():
    ep = f"tcp/127.0.0.1:{free_port()}"  # nobody listens there
    out = _cli("ps", "--connect", ep)
    assert out.returncode == 2 and "Traceback" not in out.stderr, out.stderr
    assert (
        out.stderr.strip()
        == f"error: cannot join world 'demo': no router answers at {ep} (is it running, and is this its address?)"
    )


@pytest.mark.slow
def test_own_watch_ends_with_0_on_a_closed_pipe_and_on_ctrl_c(router, world, procs):
    ep = f"tcp/127.0.0.1:{router[1]}"
    sim = procs.start(robofabric_cmd("sim", "--scene", "combined", "--world", world, "--connect", ep), name="sim")
    wait_until(lambda: router[0].live_peers("sim"), timeout=60, what="sim peer", seen=lambda: procs.output(sim)[-2000:])
    wait_until(
        lambda: _cli("own", "list", "--world", world, "--connect", ep).returncode == 0,
        timeout=30,
        what="the records served",
    )
    rc, err = _head(procs, robofabric_cmd("own", "watch", "--world", world, "--connect", ep), 2)
    assert rc == 0 and "Traceback" not in err, (rc, err)
    rc, out = _interrupt(procs, robofabric_cmd("own", "watch", "--world", world, "--connect", ep), "exclusive")
    assert rc == 0 and "Traceback" not in out, (rc, out[-2000:])
