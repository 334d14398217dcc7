"""``view --serve-web --bind ADDR``: the page and the data port listen on that address only, and the printed URL
names it; a --bind that is no IPv4 address, or without --serve-web, is refused with the reason."""

from __future__ import annotations

import re
import socket
import subprocess
import urllib.request

import pytest

from robofabric.testing import free_port, robofabric_cmd, wait_until

pytestmark = pytest.mark.slow  # a viewer process (it fetches the page from Rerun's binary at start)


def _accepts(host: str, port: int) -> bool:
    try:
        with socket.create_connection((host, port), timeout=2):
            return True
    except OSError:
        return False


def test_bind_listens_on_that_address_only(router, world, procs):
    web, grpc = free_port(), free_port()
    view = procs.start(
        robofabric_cmd(
            "view",
            "--serve-web",
            "--bind",
            "127.0.0.3",
            "--web-port",
            str(web),
            "--grpc-port",
            str(grpc),
            "--world",
            world,
            "--connect",
            f"tcp/127.0.0.1:{router[1]}",
        ),
        name="view",
    )
    url = wait_until(
        lambda: re.search(r"web viewer: open (\S+)", procs.output(view)),
        timeout=90,
        what="the viewer's URL",
        seen=lambda: procs.output(view)[-2000:],
    ).group(1)
    assert url.startswith(f"http://127.0.0.3:{web}/") and f"127.0.0.3%3A{grpc}" in url, url
    assert urllib.request.urlopen(f"http://127.0.0.3:{web}/", timeout=10).status == 200
    assert _accepts("127.0.0.3", grpc)
    assert not _accepts("127.0.0.1", web) and not _accepts("127.0.0.1", grpc)


@pytest.mark.parametrize(
    "args, why",
    [
        (["--serve-web", "--bind", "lab-pc"], "expected an IPv4 address"),
        (["--save", "x.rrd", "--bind", "127.0.0.1"], "--bind goes with --serve-web"),
    ],
)
def test_a_bad_bind_is_refused_with_the_reason(args, why, tmp_path):
    r = subprocess.run(robofabric_cmd("view", *args), capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert r.returncode != 0 and why in r.stdout + r.stderr, (r.returncode, r.stdout, r.stderr)
