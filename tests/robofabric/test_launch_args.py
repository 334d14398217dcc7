"""Launch file arguments: [args] defaults, ROBOFABRIC_NAME environment overrides, NAME=VALUE on the command line."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from robofabric.launch import LaunchError, load_launch, parse_cli_args, parse_launch
from robofabric.testing import robofabric_cmd

REPO = Path(__file__).resolve().parents[2]

LAN = """
[args]
world = "demo"
connect = "tcp/10.0.0.5:7447"
rate = 20

[launch]
world = "{world}"
connect = ["{connect}"]

[[peer]]
name = "sim"
args = ["sim", "--scene", "combined", "--rate", "{rate}", "-o", "{out}/x"]
env = { SIM_TAG = "{world}-{rate}" }
"""


def test_defaults_apply_and_unknown_placeholders_stay_for_the_supervisor():
    spec = parse_launch(LAN, "lan.toml")
    assert (spec.world, spec.connect) == ("demo", ("tcp/10.0.0.5:7447",))
    assert spec.peers[0].args == ("sim", "--scene", "combined", "--rate", "20", "-o", "{out}/x")
    assert dict(spec.peers[0].env) == {"SIM_TAG": "demo-20"}
    assert dict(spec.args) == {"world": "demo", "connect": "tcp/10.0.0.5:7447", "rate": "20"}


def test_command_line_beats_environment_beats_default():
    env = {"ROBOFABRIC_CONNECT": "tcp/10.0.0.7:7447,tcp/10.0.0.8:7447", "ROBOFABRIC_WORLD": "envworld"}
    spec = parse_launch(LAN, "lan.toml", env=env)
    assert spec.world == "envworld" and spec.connect == ("tcp/10.0.0.7:7447", "tcp/10.0.0.8:7447")
    spec = parse_launch(LAN, "lan.toml", args=parse_cli_args(["world=lab2", "rate=50"]), env=env)
    assert spec.world == "lab2" and spec.connect == ("tcp/10.0.0.7:7447", "tcp/10.0.0.8:7447")
    assert spec.peers[0].args[4] == "50" and dict(spec.peers[0].env) == {"SIM_TAG": "lab2-50"}


def test_builtin_arguments_work_on_files_that_declare_none():
    text = '[launch]\nworld = "demo"\nrouter = "tcp/127.0.0.1:7447"\n[[peer]]\nname = "a"\nargs = ["sim"]\n'
    spec = parse_launch(text, "plain.toml", args={"world": "lab2", "connect": "tcp/10.0.0.5:7447"})
    assert (spec.world, spec.router, spec.connect) == ("lab2", "tcp/127.0.0.1:7447", ("tcp/10.0.0.5:7447",))
    # the environment does not touch a file that declares no arguments (a demo must not follow ROBOFABRIC_CONNECT)
    assert parse_launch(text, "plain.toml", env={"ROBOFABRIC_CONNECT": "tcp/10.9.9.9:1"}).connect == ()


@pytest.mark.parametrize(
    ("args", "text", "says"),
    [
        (["nope=1"], LAN, "unknown launch argument(s) nope; this file takes connect, rate, router, world"),
        (["world=a b"], LAN, "world 'a b'"),
        ([], '[args]\nx = ["a"]\n', "[args] x must have a string or number default"),
    ],
)
def test_mistakes_name_the_file_and_the_argument(args, text, says):
    with pytest.raises(LaunchError, match="lan.toml|bad.toml") as err:
        parse_launch(text, "lan.toml" if text is LAN else "bad.toml", args=parse_cli_args(args))
    assert says in str(err.value)


def test_cli_args_must_be_name_value():
    with pytest.raises(LaunchError, match="is not NAME=VALUE"):
        parse_cli_args(["tcp/10.0.0.5:7447"])


def test_shipped_lan_files_take_the_router_address_as_an_argument():
    for name in ("sim", "compute", "users", "viewer"):
        spec = load_launch(
            REPO / "examples" / "lan" / f"{name}.toml", args={"connect": "tcp/192.0.2.1:7447", "world": "lab2"}
        )
        assert spec.connect == ("tcp/192.0.2.1:7447",) and spec.world == "lab2", name
    spec = load_launch(REPO / "examples" / "lan" / "router.toml", env={"ROBOFABRIC_ROUTER": "tcp/0.0.0.0:7448"})
    assert spec.router == "tcp/0.0.0.0:7448"


@pytest.mark.slow
def test_up_reports_a_bad_argument_in_one_line(tmp_path):
    out = subprocess.run(
        robofabric_cmd("up", str(REPO / "examples" / "lan" / "sim.toml"), "conect=tcp/x:1"),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert (
        out.returncode == 2 and "unknown launch argument(s) conect" in out.stderr and "Traceback" not in out.stderr
    ), out.stderr
