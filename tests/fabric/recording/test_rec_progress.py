"""Progress bars (rich, on stderr) on ``replay`` and ``export``; ``--quiet`` turns them off."""

from __future__ import annotations

import pytest

import subprocess

from rec_helpers import synthetic, write_recording

from fabric.testing import robofabric_cmd


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(robofabric_cmd(*args), capture_output=True, text=True, timeout=120)


@pytest.mark.slow
def test_replay_and_export_show_progress_unless_quiet(tmp_path, world, router):
    src = tmp_path / "small.mcap"
    samples = synthetic(world, n=20)
    write_recording(src, samples)
    fabric_msgs = len(samples) - 1  # the raw blob is replayed too; export skips it
    ep = f"tcp/127.0.0.1:{router[1]}"
    out = _cli("replay", str(src), "--speed", "20", "--wait", "0", "--world", world, "--connect", ep)
    assert out.returncode == 0, out.stderr
    assert f"{len(samples)}/{len(samples)}" in out.stderr and "━" in out.stderr, out.stderr  # rich's bar
    quiet = _cli("replay", str(src), "--speed", "20", "--wait", "0", "-q", "--world", world, "--connect", ep)
    assert quiet.returncode == 0 and "━" not in quiet.stderr and f"{len(samples)}/{len(samples)}" not in quiet.stderr, quiet.stderr

    exp = _cli("export", str(src), "-o", str(tmp_path / "f.mcap"), "--to", "foxglove")
    assert exp.returncode == 0, exp.stderr
    assert f"{len(samples)}/{len(samples)}" in exp.stderr and f"exported {fabric_msgs} messages" in exp.stdout, exp.stderr + exp.stdout
