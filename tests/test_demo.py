"""`robofabric demo`: the embedded default runs in one command and exits 0 with a summary."""

import subprocess

from fabric.testing import free_port, robofabric_cmd


def test_demo_runs_and_summarises(tmp_path):
    port = free_port()
    out = subprocess.run(
        robofabric_cmd("demo", "--duration", "8", "--out", str(tmp_path), "--router", f"tcp/127.0.0.1:{port}"),
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    assert "demo summary" in out.stdout
    assert "ok" in out.stdout.splitlines()[-1]
