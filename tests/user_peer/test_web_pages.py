"""Several browser pages on one ``view --serve-web``, one of them frozen: the others are not held up.

Rerun's gRPC server feeds its clients through one bounded broadcast channel whose sender waits for the
slowest client, so without the relay (user_peer/web_relay.py) a page that stops taking data (its JavaScript
paused here with CDP ``Debugger.pause``, as a laptop gone to sleep) stops the view for every page once that
channel fills. The test pauses one page and keeps it paused until the viewer says the relay cut it off (its
page took nothing for 10 s while its data waited: proof that it held data it did not take), or for 75 s at most (the browser's own
network buffers absorb a paused page's data for 40 s to over two minutes here); meanwhile every other page's own time
cursor (read from the page, robofabric/bench/viewer_web.py) must go on advancing at no less than half
the wall clock's pace, and Rerun's server must never report its sender blocked.

Pages: three live + one frozen, 640x400, on this 2-core machine with software WebGL (each page then
draws at 1.5-2 frames a second, which sets how live it can be: docs/viewer.md); the viewer sends pages
0.5 s windows thinned to 5 Hz per stream (``--window 0.5 --max-hz 5``).
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

from robofabric.testing import free_port, robofabric_cmd, wait_until

pytestmark = pytest.mark.slow

LIVE_PAGES = 3
FROZEN_S = 75.0  # the longest the frozen page stays paused (sooner when the relay cuts it off)
BASELINE_S = 20.0  # how long the live pages' own pace is measured before one is frozen (a window, not a wait)
VIEWPORT = {"width": 640, "height": 400}


def test_a_frozen_page_does_not_hold_up_the_others(router, world, procs, tmp_path):
    from playwright.sync_api import sync_playwright

    from robofabric.bench.viewer_web import CHROMIUM, CHROMIUM_ARGS, open_pages, page_lag
    from tests.user_peer.test_view_web import WORLD_VIEW, robot_pixels

    assert Path(CHROMIUM).exists() and shutil.which("chromium"), "Debian's chromium is not installed (apt-get install chromium)"
    ep = f"tcp/127.0.0.1:{router[1]}"
    procs.start(robofabric_cmd("sim", "--scene", "combined", "--world", world, "--connect", ep), name="sim")
    web, grpc = free_port(), free_port()
    view = procs.start(robofabric_cmd(
        "view", "--serve-web", "--advertise", "127.0.0.1", "--web-port", str(web), "--grpc-port", str(grpc),
        "--window", "0.5", "--max-hz", "5", "--world", world, "--connect", ep), name="view")
    url = wait_until(lambda: re.search(r"web viewer: open (http://\S+)", procs.output(view)), timeout=60,
                     what="the viewer to print its URL", seen=lambda: procs.output(view)[-2000:]).group(1)

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS)
        try:
            pages = open_pages(browser, url, LIVE_PAGES + 1, VIEWPORT)
            wait_until(lambda: all(page_lag(pg) is not None for pg in pages), timeout=240, interval=2.0,
                       what="every page to show the live world", seen=lambda: [page_lag(pg) for pg in pages])
            live, frozen = pages[:LIVE_PAGES], pages[LIVE_PAGES]
            # the pages' own pace with none frozen, side by side: what software GL on this box draws (a 2-core
            # box's four pages have kept up with the wall clock, and have not: 0.35x with Chromium 150)
            b0 = time.time()
            before = [b0 - page_lag(pg) for pg in live]
            time.sleep(BASELINE_S)
            b1 = time.time()
            pace = [(b1 - page_lag(pg) - s) / (b1 - b0) for pg, s in zip(live, before)]
            cdp = frozen.context.new_cdp_session(frozen)
            cdp.send("Debugger.enable")
            cdp.send("Debugger.pause")
            t0 = time.time()
            start = [t0 - page_lag(pg) for pg in live]  # each page's time cursor (wall clock s) at the pause
            # frozen until the relay cuts it off (it took nothing for 10 s while its data waited) or
            # FROZEN_S, whichever first: how soon the cut comes depends on how much the browser's own network
            # buffers absorb for a paused page (40 s to over 2 min here), so the test does not wait on it
            deadline = time.monotonic() + FROZEN_S
            while (cut := re.search(r"web relay: page \S+ cut off: (.*)", procs.output(view))) is None and time.monotonic() < deadline:
                time.sleep(1.0)
            t1 = time.time()
            end = [t1 - page_lag(pg) for pg in live]
            shot = tmp_path / "web-pages.png"
            shot.write_bytes(base64.b64decode(live[0].context.new_cdp_session(live[0]).send(
                "Page.captureScreenshot", {"format": "png"})["data"]))
            lags = [round(page_lag(pg), 2) for pg in live]
        finally:
            browser.close()
    keep = Path(__file__).resolve().parents[2] / "out" / "test-web-pages.png"
    keep.parent.mkdir(exist_ok=True)
    shutil.copy(shot, keep)
    advanced = [(e - s) / (t1 - t0) for s, e in zip(start, end)]
    out = procs.output(view)
    assert "has been blocked" not in out, out[-3000:]
    # held up, a page's cursor stops (0x); not held up, it keeps at least half its own pace before the freeze
    assert all(a >= 0.5 * min(1.0, p) and a > 0.05 for a, p in zip(advanced, pace)), (
        f"pages' time cursors advanced {advanced} x the wall clock over {t1 - t0:.0f} s with one page frozen "
        f"({cut.group(1) if cut else 'not cut off yet'}), against {pace} before it froze; lags now {lags}")
    rgb = np.asarray(Image.open(keep).convert("RGB"))
    assert robot_pixels(rgb[WORLD_VIEW]) >= 30, f"a live page does not show the robots: {keep}"
    assert view.poll() is None, out[-3000:]
