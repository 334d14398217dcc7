"""Shell completion: the completers themselves (keys from a live world, types, formats, scenarios), and one
completion through typer's own mechanism in a child process, as bash asks for it."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from fabric import keys
from robofabric.complete import complete_export_formats, complete_formats, complete_keys, complete_types, live_keys
from fabric.interfaces import Header, JointState, WorldInfo
from robofabric.testing import free_port, robofabric_cmd, wait_until


class _Ctx:
    """What typer hands a completer: the parameters parsed so far, and the parent's."""

    def __init__(self, params: dict, parent: "_Ctx | None" = None) -> None:
        self.params = params
        self.parent = parent


def test_types_and_formats_complete_from_what_is_installed():
    assert {"JointState", "JointTarget"} <= set(complete_types("Joint")) and all(
        t.startswith("Joint") for t in complete_types("Joint")
    )
    assert complete_types("Nope") == []
    assert complete_formats("") == ["foxglove", "ros2"] and complete_formats("f") == ["foxglove"]
    assert complete_export_formats("r") == ["ros2", "rrd"]


def test_scenario_names_complete():
    from user_peer.cli import complete_scenarios

    assert complete_scenarios("test-") == ["test-a", "test-b"] and complete_scenarios("x") == []


def test_keys_of_a_live_world_complete_world_relative_or_full(router, connect, world):
    sim = connect("sim", peer_id="sim-c")
    sim.rpc.serve(keys.srv(world, "world"), lambda k, r: WorldInfo(world=world))
    sim.subscribe_raw(keys.robot_cmd_all(world, "arm1"), lambda s: None)
    stop = threading.Event()

    def run() -> None:
        i = 0
        while not stop.wait(0.02):
            sim.publish(
                keys.robot_joints(world, "arm1"),
                JointState(("j1",), np.zeros(1), np.zeros(1), Header.now(seq=i, source="sim-c")),
            )
            i += 1

    t = threading.Thread(target=run, daemon=True)
    t.start()
    try:
        ctx = _Ctx({"world": world, "connect": [f"tcp/127.0.0.1:{router[1]}"]})
        # what the router knows of a peer just joined (its token, its queryable, its subscriber) reaches a new
        # session in its own time on a loaded box: completion is asked again until it lists them, with a deadline
        want = {
            "robot/arm1/joints",
            "srv/world",
            "peer/sim/sim-c",
            keys.robot_cmd_all(world, "arm1").removeprefix(f"rf/{world}/"),
        }
        seen: list[list[str]] = [[]]

        def complete_all() -> bool:
            seen[0] = complete_keys(ctx, "")
            return want <= set(seen[0])

        wait_until(complete_all, timeout=30, what="the live world's keys among the completions", seen=lambda: seen[0])
        got = seen[0]
        assert keys.robot_cmd_all(world, "arm1").removeprefix(f"rf/{world}/") in got, got  # a subscriber's expression
        assert complete_keys(ctx, "robot/") == [k for k in got if k.startswith("robot/")]
        assert keys.robot_joints(world, "arm1") in complete_keys(ctx, f"rf/{world}/robot/")  # full keys when typed full
        # the root's options (robofabric --world W list <TAB>) count too
        assert "srv/world" in complete_keys(_Ctx({}, parent=ctx), "srv/")
        from robofabric.complete import complete_peers

        assert complete_peers(ctx, "sim-") == ["sim-c"]
    finally:
        stop.set()
        t.join(timeout=5)


def test_keys_complete_to_nothing_without_a_router_and_do_not_hang():
    start = time.monotonic()
    assert live_keys("w", [f"tcp/127.0.0.1:{free_port()}"]) == []
    assert complete_keys(_Ctx({"world": "w", "connect": [f"tcp/127.0.0.1:{free_port()}"]}), "") == []
    assert time.monotonic() - start < 4.0  # two tries, each given up after ~0.6 s


@pytest.mark.slow
def test_the_completion_module_imports_no_session_library():
    out = subprocess.run(
        [
            sys.executable,
            "-c",
            "import sys, robofabric.complete; print('zenoh' in sys.modules, 'numpy' in sys.modules)",
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 0 and out.stdout.split() == ["False", "False"], out.stdout + out.stderr


@pytest.mark.slow
@pytest.mark.parametrize(
    ("words", "expected"),
    [
        (["export", "a.mcap", "-o", "b.mcap", "--to", "r"], ["ros2", "rrd"]),
        (["record", "-o", "x.mcap", "--to", ""], ["foxglove", "ros2"]),
        (["scenario", "test"], ["test-a", "test-b"]),
    ],
)
def test_bash_completion_through_typer(words, expected):
    line = ["robofabric", *words]
    env = {
        **os.environ,
        "_ROBOFABRIC_COMPLETE": "complete_bash",
        "COMP_WORDS": " ".join(line),
        "COMP_CWORD": str(len(line) - 1),
    }
    out = subprocess.run(robofabric_cmd(), capture_output=True, text=True, timeout=60, env=env)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == expected, out.stdout


def test_info_completes_recordings_and_folders_here_and_nothing_else_for_a_path(tmp_path, monkeypatch):
    from robofabric.complete import complete_keys_or_recordings

    (tmp_path / "run1.mcap").write_bytes(b"")
    (tmp_path / "runs").mkdir()
    (tmp_path / "run.txt").write_text("")
    monkeypatch.chdir(tmp_path)
    no_router = _Ctx({"world": "w", "connect": [f"tcp/127.0.0.1:{free_port()}"]})
    assert complete_keys_or_recordings(no_router, "ru") == ["run1.mcap", "runs/"]
    assert complete_keys_or_recordings(no_router, "./ru") == ["./run1.mcap", "./runs/"]
