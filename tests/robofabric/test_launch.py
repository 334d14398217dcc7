"""Launch files: checked before anything starts; supervised peers; the demo skeleton."""

import subprocess

import pytest

from robofabric.launch import LaunchError, parse_launch
from robofabric.testing import free_port, robofabric_cmd

GOOD = """
[launch]
world = "lab"
router = "tcp/0.0.0.0:7447"

[[peer]]
name = "sim"
args = ["sim", "--scene", "combined"]

[[peer]]
name = "alice"
args = ["scenario", "test-a", "--out", "{out}"]
role = "task"
after = ["sim"]
"""


def test_parse_good_file():
    spec = parse_launch(GOOD, "good.toml")
    assert spec.world == "lab"
    assert spec.child_connect() == ("tcp/127.0.0.1:7447",)
    sim, alice = spec.peers
    assert sim.role == "service" and sim.restart == "on-failure" and sim.ready == "peer/sim/*"
    assert alice.role == "task" and alice.restart == "no" and alice.after == ("sim",)


@pytest.mark.parametrize(
    "text,needle",
    [
        ("[launch]\nworld = \n", "bad.toml: "),
        (
            '[[peer]]\nname = "a"\nargs = ["sim"]\n\n[[peer]]\nname = "b"\nargs = ["x"]\nrole = "daemon"\n',
            "bad.toml:5: peer 'b' has role 'daemon'",
        ),
        ('[[peer]]\nname = "a"\nargs = []\n', "bad.toml:1: peer 'a' needs args"),
        ('[[peer]]\nname = "a"\nargs = ["sim"]\nafter = ["ghost"]\n', "starts after ghost"),
        (
            '[[peer]]\nname = "a"\nargs = ["sim"]\n[[peer]]\nname = "a"\nargs = ["sim"]\n',
            "bad.toml:4: peer name 'a' is used twice",
        ),
        ('[launch]\nworld = "a b"\n', "world 'a b' contains forbidden"),
        ("[robots]\nx = 1\n", "unknown section(s) robots"),
        ('[[peer]]\nname = "a"\nargs = ["sim"]\ncolour = "red"\n', "unknown key(s) colour"),
        # a ready expression zenoh refuses, or no string at all, is named with its line before anything starts
        (
            '[[peer]]\nname = "a"\nargs = ["sim"]\nready = "peer/**/**"\n',
            "bad.toml:1: peer 'a' ready: 'peer/**/**' is not a valid key expression",
        ),
        ('[[peer]]\nname = "a"\nargs = ["sim"]\nready = 3\n', "bad.toml:1: peer 'a' ready must be a key expression"),
    ],
)
def test_bad_files_name_file_and_line(text, needle):
    with pytest.raises(LaunchError) as err:
        parse_launch(text, "bad.toml")
    assert needle in str(err.value)


def _up(tmp_path, text, *extra, timeout=90):
    f = tmp_path / "launch.toml"
    f.write_text(text)
    port = free_port()
    return subprocess.run(
        robofabric_cmd("up", str(f), "--out", str(tmp_path / "out"), "--router", f"tcp/127.0.0.1:{port}", *extra),
        capture_output=True,
        text=True,
        timeout=timeout,
    )


@pytest.mark.slow
def test_up_restarts_a_failing_service_up_to_its_limit(tmp_path, world):
    text = f"""
[launch]
world = "{world}"

[[peer]]
name = "flaky"
args = ["pub", "robot/x/cmd/stop", "-t", "NoSuchType"]
restart = "on-failure"
max_restarts = 2
"""
    out = _up(tmp_path, text, "--duration", "60")
    assert "restart 2/2" in out.stdout, out.stdout
    assert "flaky exited with code 2; not restarted" in out.stdout
    assert "every peer exited" in out.stdout
    assert out.stdout.count("unknown message type 'NoSuchType'") == 3


@pytest.mark.slow
def test_up_runs_a_task_and_reports_it(tmp_path, world):
    text = f"""
[launch]
world = "{world}"

[[peer]]
name = "once"
args = ["pub", "robot/x/cmd/stop", "-t", "Stop", "--user", "ann", "--wait", "0"]
role = "task"
"""
    out = _up(tmp_path, text, "--duration", "40")
    assert "once finished with exit code 0" in out.stdout
    assert "published 1 Stop" in out.stdout
    assert out.returncode == 0, out.stdout + out.stderr
    assert (tmp_path / "out" / "logs" / "once.log").read_text().strip().endswith(f"rf/{world}/robot/x/cmd/stop/by/ann")


@pytest.mark.slow
def test_failed_task_fails_the_launch(tmp_path, world):
    text = f'[launch]\nworld = "{world}"\n[[peer]]\nname = "bad"\nargs = ["pub", "robot/x/cmd/stop", "-t", "Nope"]\nrole = "task"\n'
    out = _up(tmp_path, text, "--duration", "40")
    assert out.returncode == 1
    assert "failed: bad" in out.stdout


@pytest.mark.slow
def test_bad_launch_file_is_one_line_exit_2(tmp_path):
    out = _up(tmp_path, '[[peer]]\nname = "a"\nargs = "sim"\n')
    assert out.returncode == 2
    assert "launch.toml:1: peer 'a' needs args" in out.stderr and "Traceback" not in out.stderr


def test_shipped_launch_files_parse():
    from pathlib import Path

    from robofabric.launch import load_launch

    root = Path(__file__).resolve().parents[2] / "examples"
    # examples/lab/ holds `robofabric lab` files (hosts of a namespace LAN), not launch files
    files = sorted(p for p in root.rglob("*.toml") if p.relative_to(root).parts[0] != "lab")
    assert len(files) >= 5
    for f in files:
        spec = load_launch(f)
        assert spec.child_connect(), f


def test_peer_logs_rotate(tmp_path):
    import io

    from robofabric.launch import Supervisor

    sup = Supervisor(
        parse_launch(GOOD, "good.toml"),
        out_dir=tmp_path,
        is_ready=lambda e: True,
        console=io.StringIO(),
        log_max_bytes=2_000,
        log_backups=2,
    )
    lines = b"".join(b"line %05d of a chatty peer\n" % i for i in range(1_000))  # ~27 kB
    sup.pump("sim", io.BytesIO(lines), tmp_path / "logs" / "sim.log")
    logs = sorted(p.name for p in (tmp_path / "logs").iterdir())
    assert logs == ["sim.log", "sim.log.1", "sim.log.2"]
    assert all((tmp_path / "logs" / n).stat().st_size <= 2_000 for n in logs)
    assert (tmp_path / "logs" / "sim.log").read_text().rstrip().endswith("line 00999 of a chatty peer")
    assert sup.peers["sim"].last_line == "line 00999 of a chatty peer"
