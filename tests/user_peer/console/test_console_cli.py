"""``robofabric console`` as a command: its mistakes, the URL it prints, a clean end on Ctrl-C."""

from __future__ import annotations

import signal
import subprocess
import urllib.request

import pytest

from robofabric.secure import init
from robofabric.testing import free_port, robofabric_cmd, wait_until

pytestmark = pytest.mark.slow


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(robofabric_cmd(*args), capture_output=True, text=True, timeout=60)


@pytest.mark.parametrize(
    "args,needle",
    [
        (("--listen", "8080"), "expected HOST:PORT"),
        (("--listen", "0.0.0.0:99999"), "expected HOST:PORT"),
        (("--grace", "-1"), "--grace must be >= 0"),
        (("--view-fps", "0"), "expected 1 to 60 frames a second"),
    ],
)
def test_mistakes_give_one_line_and_exit_2(args, needle):
    out = _run("console", "--connect", "tcp/127.0.0.1:1", *args)
    assert out.returncode == 2 and needle in out.stderr and "Traceback" not in out.stderr, out.stderr


def test_a_config_that_logs_in_is_refused(tmp_path):
    """The console holds no login of its own: a student's NAME.json5 as its base config is refused."""
    files = init(tmp_path / "class", users=["alice"], listen=["tcp/127.0.0.1:7447"]).clients
    out = _run("console", "--zenoh-config", str(files["alice"]))
    assert out.returncode == 2 and "holds no login of its own" in out.stderr, out.stderr


def test_it_prints_the_url_serves_the_page_and_ends_on_ctrl_c(router, world, procs):
    port = free_port()
    con = procs.start(
        robofabric_cmd(
            "console", "--world", world, "--connect", f"tcp/127.0.0.1:{router[1]}", "--listen", f"127.0.0.1:{port}"
        ),
        name="console",
    )
    url = f"http://127.0.0.1:{port}/"
    wait_until(
        lambda: f"console: open {url}" in procs.output(con),
        timeout=60,
        what="the URL",
        seen=lambda: procs.output(con)[-2000:],
    )
    with urllib.request.urlopen(url, timeout=10) as r:
        page = r.read().decode()
    assert r.status == 200 and "robofabric console" in page
    con.send_signal(signal.SIGINT)
    assert con.wait(timeout=20) == 0, procs.output(con)[-2000:]
    assert "Traceback" not in procs.output(con)
