"""The record/info/replay commands: key filters and remap through the CLI, and bad input (one line, exit 2)."""

import json
import subprocess
from collections import Counter

import pytest

from fabric import keys
from fabric.recording import Recorder
from user_peer.recordings import iter_messages, read_info
from robofabric.testing import robofabric_cmd, wait_until

from tests.fabric.recording.rec_helpers import synthetic, write_recording

pytestmark = pytest.mark.slow  # every test here starts processes or runs for seconds


def run_cli(*args, timeout=60):
    return subprocess.run(robofabric_cmd(*args), capture_output=True, text=True, timeout=timeout)


def _one_error_line(out):
    errors = [line for line in out.stderr.splitlines() if line.startswith("error:")]
    assert out.returncode == 2, (out.returncode, out.stderr)
    assert len(errors) == 1 and "Traceback" not in out.stderr, out.stderr
    return errors[0]


@pytest.fixture
def small(tmp_path):
    path = tmp_path / "small.mcap"
    samples = synthetic("w", n=30, dt_ns=5_000_000)
    write_recording(path, samples)
    return path, samples


def test_replay_with_a_key_filter_into_another_world(small, world, router, connect):
    path, samples = small
    out = path.parent / "filtered.mcap"
    rec_fab = connect("recorder", "rec")
    with Recorder(rec_fab, out) as rec:
        r = run_cli(
            "replay",
            str(path),
            "--keys",
            "robot/r0/*",
            "--world",
            "w",
            "--remap-world",
            world,
            "--speed",
            "4",
            "--connect",
            f"tcp/127.0.0.1:{router[1]}",
        )
        assert r.returncode == 0, r.stderr
        want = Counter(k.replace("rf/w/", f"rf/{world}/") for k, _, _ in samples if k.startswith("rf/w/robot/r0/"))
        wait_until(lambda: rec.stats.messages >= sum(want.values()), what="the filtered replay", seen=lambda: rec.stats)
    got = list(iter_messages(out))
    assert Counter(m.key for m in got) == want
    assert [m.payload for m in got] == [p for k, _, p in samples if k.startswith("rf/w/robot/r0/")]


def test_info_json_describes_the_file(small):
    path, samples = small
    r = run_cli("info", str(path), "--json")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["complete"] and doc["messages"] == len(samples) and doc["worlds"] == ["w"]
    assert {c["key"]: c["messages"] for c in doc["channels"]} == dict(Counter(k for k, _, _ in samples))
    table = run_cli("info", str(path))
    assert "complete" in table.stdout and "rf/w/robot/r0/scan" in table.stdout and "JointState" in table.stdout


@pytest.mark.parametrize(
    "content, why",
    [
        (None, "no such file"),
        (b"GIF89a....", "not an MCAP file"),
        (b"\x89MCAP0\r\n\x01\x02", "truncated beyond repair"),
    ],
)
@pytest.mark.parametrize("command", ["info", "replay"])
def test_bad_files(tmp_path, content, why, command):
    path = tmp_path / "bad.mcap"
    if content is not None:
        path.write_bytes(content)
    line = _one_error_line(
        run_cli(command, str(path), "--connect", "tcp/127.0.0.1:1")
        if command == "replay"
        else run_cli(command, str(path))
    )
    assert why in line


@pytest.mark.parametrize(
    "args, why",
    [
        (["--world", "nope"], "world 'nope' is not in"),
        (["--keys", "robot/zz/**"], "nothing in"),
        (["--keys", "robot/**/x$$"], "not a valid key expression"),
        (["--speed", "0"], "--speed must be a positive"),
        (["--start", "50"], "no selected message between"),
    ],
)
def test_impossible_replays(small, args, why):
    path, _ = small
    line = _one_error_line(run_cli("replay", str(path), *args, "--connect", "tcp/127.0.0.1:1"))
    assert why in line


def test_empty_recording_cannot_be_replayed(tmp_path):
    path = tmp_path / "empty.mcap"
    write_recording(path, [])
    assert read_info(path).messages == 0 and read_info(path).complete
    assert "holds no messages" in _one_error_line(run_cli("replay", str(path)))


def test_record_refuses_bad_arguments_before_joining(tmp_path):
    assert "not a valid key expression" in _one_error_line(
        run_cli("record", "-o", str(tmp_path / "a.mcap"), "robot/**/x$$")
    )
    assert "does not exist" in _one_error_line(run_cli("record", "-o", str(tmp_path / "no" / "a.mcap")))
    assert "is a directory" in _one_error_line(run_cli("record", "-o", str(tmp_path)))
    assert "--compression" in _one_error_line(run_cli("record", "-o", str(tmp_path / "a.mcap"), "--compression", "zip"))


def test_recording_an_unknown_world_says_nothing_was_recorded(tmp_path, router):
    path = tmp_path / "silent.mcap"
    out = run_cli(
        "record", "-o", str(path), "--world", "nobodyhere", "--duration", "1", "--connect", f"tcp/127.0.0.1:{router[1]}"
    )
    assert out.returncode == 1 and "Traceback" not in out.stderr, (out.returncode, out.stderr)  # the world had nothing
    line = out.stderr.strip().splitlines()[-1]
    assert "nothing was recorded on rf/nobodyhere/**" in line
    info = read_info(path)  # still a valid, finished (empty) file
    assert info.complete and info.messages == 0
    assert keys.world_all("nobodyhere") in line
