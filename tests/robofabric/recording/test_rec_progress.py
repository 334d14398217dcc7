"""Progress bars (rich, on stderr) on ``replay`` and ``export``; ``--quiet`` turns them off."""

from __future__ import annotations

import subprocess

import pytest
from tests.fabric.recording.rec_helpers import synthetic, write_recording

from robofabric.testing import robofabric_cmd


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
    assert quiet.returncode == 0 and "━" not in quiet.stderr and f"{len(samples)}/{len(samples)}" not in quiet.stderr, (
        quiet.stderr
    )

    exp = _cli("export", str(src), "-o", str(tmp_path / "f.mcap"), "--to", "foxglove")
    assert exp.returncode == 0, exp.stderr
    assert f"{len(samples)}/{len(samples)}" in exp.stderr and f"exported {fabric_msgs} messages" in exp.stdout, (
        exp.stderr + exp.stdout
    )


def test_info_reports_its_progress_through_the_file(tmp_path, world):
    from user_peer.recordings import read_info

    src = tmp_path / "info.mcap"
    write_recording(src, synthetic(world, n=1500), chunk_size=4096)
    seen: list[tuple[int, int]] = []
    inf = read_info(src, progress=lambda done, total: seen.append((done, total)))
    size = src.stat().st_size
    assert inf.messages > 2000 and len(seen) >= 2
    assert (
        all(t == size for _, t in seen)
        and [d for d, _ in seen] == sorted(d for d, _ in seen)
        and seen[-1] == (size, size)
    )
    assert 0 < seen[0][0] < size  # reported while reading, not only at the end
