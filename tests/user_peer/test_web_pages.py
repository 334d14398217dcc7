"""A browser page on one ``view --serve-web`` frozen: the other pages are not held up.

Rerun's gRPC server feeds its clients through one bounded broadcast channel whose sender waits for the
slowest client, so without the relay (user_peer/web_relay.py) a page that stops taking data (its JavaScript
paused here with CDP ``Debugger.pause``, as a laptop gone to sleep) stops the view for every page once that
channel fills. The test shows one real page (Debian's chromium, software WebGL, 640x400) the live world, then
pauses it until the viewer says the relay cut it off (it took nothing for 10 s while its data waited: proof
that it held data it did not take), or for 75 s at most (the browser's own network buffers absorb a paused
page's data for 40 s to over two minutes here). Meanwhile the other page, a reader that takes its data as fast
as it comes (gRPC-web from Python: the bytes a page gets), must go on receiving at no less than half its rate
before the freeze, and Rerun's server must never report its sender blocked.

The other page is not a browser: how fast a page draws with software GL is the box's, not the relay's (four
pages drew at 0.35x the wall clock with Chromium 150 on this 2-core box, and at about 0x on CI's Chromium 156;
docs/viewer.md has the figures of ``bench viewer-web``). The viewer sends pages 0.5 s windows thinned to 5 Hz
per stream (``--window 0.5 --max-hz 5``).
"""

from __future__ import annotations

import base64
import re
import shutil
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from robofabric.bench.grpc_web import WebReader
from robofabric.testing import free_port, robofabric_cmd, wait_until

pytestmark = pytest.mark.slow

CUT = r"web relay: page \S+ cut off: (.*)"
FROZEN_S = 75.0  # the longest the frozen page stays paused (sooner when the relay cuts it off)
BASELINE_S = 20.0  # how long the other page's pace is measured before the freeze (a window, not a wait)
VIEWPORT = {"width": 640, "height": 400}
SHOW_S = 400.0  # until the page shows the live world and its robots: minutes with software GL on a loaded box


def shows_robots(png: Path) -> bool:
    """The page's world view, in a screenshot, has robot-coloured pixels (tests/user_peer/test_view_web.py)."""
    from tests.user_peer.test_view_web import WORLD_VIEW, robot_pixels

    return robot_pixels(np.asarray(Image.open(png).convert("RGB"))[WORLD_VIEW]) >= 30


@pytest.mark.timeout(600)  # a page takes minutes to show the world with software GL on a loaded box
def test_a_frozen_page_does_not_hold_up_the_others(router, world, procs, tmp_path):
    from playwright.sync_api import sync_playwright

    from robofabric.bench.viewer_web import CHROMIUM, CHROMIUM_ARGS, open_pages, page_lag

    assert Path(CHROMIUM).exists() and shutil.which("chromium"), (
        "Debian's chromium is not installed (apt-get install chromium)"
    )
    ep = f"tcp/127.0.0.1:{router[1]}"
    procs.start(robofabric_cmd("sim", "--scene", "combined", "--world", world, "--connect", ep), name="sim")
    web, grpc = free_port(), free_port()
    view = procs.start(
        robofabric_cmd(
            "view",
            "--serve-web",
            "--advertise",
            "127.0.0.1",
            "--web-port",
            str(web),
            "--grpc-port",
            str(grpc),
            "--window",
            "0.5",
            "--max-hz",
            "5",
            "--world",
            world,
            "--connect",
            ep,
        ),
        name="view",
    )
    url = wait_until(
        lambda: re.search(r"web viewer: open (http://\S+)", procs.output(view)),
        timeout=60,
        what="the viewer to print its URL",
        seen=lambda: procs.output(view)[-2000:],
    ).group(1)

    # the other page: it takes its data as fast as it comes (gRPC-web from Python, as a browser sends it), so the
    # relay's contract is read in its bytes, whatever pace the box's software GL draws at. It joins first, so
    # its share of the history is long taken when its pace is measured.
    reader = WebReader(grpc)
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS)
        try:
            wait_until(lambda: reader.received > 0, timeout=60, what="the reader to receive", seen=lambda: reader.ended)
            (page,) = open_pages(browser, url, 1, VIEWPORT)
            shown = time.monotonic() + SHOW_S
            wait_until(
                lambda: page_lag(page) is not None, timeout=SHOW_S, interval=2.0, what="the page to show the live world"
            )
            # its time cursor comes before its 3D view has drawn the scene (at load 9 a shot then held the bare
            # grid): shots until the robots show, within the same deadline; the assertion below judges the last
            shot = tmp_path / "web-pages.png"
            cdp = page.context.new_cdp_session(page)
            while True:
                shot.write_bytes(base64.b64decode(cdp.send("Page.captureScreenshot", {"format": "png"})["data"]))
                if shows_robots(shot) or time.monotonic() > shown:
                    break
                time.sleep(2.0)
            b0, got0 = time.monotonic(), reader.received
            time.sleep(BASELINE_S)  # a window to measure the reader's pace in, not a wait
            b1, got1 = time.monotonic(), reader.received
            rate = (got1 - got0) / (b1 - b0)
            cuts = len(re.findall(CUT, procs.output(view)))
            cdp = page.context.new_cdp_session(page)
            cdp.send("Debugger.enable")
            cdp.send("Debugger.pause")
            t0, got2 = time.monotonic(), reader.received
            # frozen until the relay cuts it off (it took nothing for 10 s while its data waited) or FROZEN_S,
            # whichever first: how soon the cut comes depends on how much the browser's own network buffers
            # absorb for a paused page (40 s to over 2 min here), so the test does not wait on it
            deadline = t0 + FROZEN_S
            while len(found := re.findall(CUT, procs.output(view))) == cuts and time.monotonic() < deadline:
                time.sleep(1.0)
            t1, got3, ended = time.monotonic(), reader.received, reader.ended
        finally:
            browser.close()
            reader.close()
    keep = Path(__file__).resolve().parents[2] / "out" / "test-web-pages.png"
    keep.parent.mkdir(exist_ok=True)
    shutil.copy(shot, keep)
    frozen_rate = (got3 - got2) / (t1 - t0)
    out = procs.output(view)
    assert "has been blocked" not in out, out[-3000:]
    # held up, the other page takes nothing: not held up, it goes on at no less than half its rate before
    assert rate > 0 and frozen_rate >= 0.5 * rate and not ended, (
        f"over {t1 - t0:.0f} s with a page frozen ({found[cuts:] or 'not cut off yet'}), the other took "
        f"{frozen_rate:.0f} B/s against {rate:.0f} before ({ended or 'still open'})"
    )
    assert shows_robots(keep), f"the page did not show the robots before it froze: {keep}"
    assert view.poll() is None, out[-3000:]
