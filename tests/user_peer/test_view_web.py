"""``robofabric view --serve-web --advertise HOST``: the plain ``http://HOST:PORT/`` shows the live world in a
browser elsewhere, and the page asks nothing of any other host.

"Elsewhere" is played by the address 127.0.0.2: the page is loaded from ``http://127.0.0.2:PORT/``
(not ``localhost``, so Rerun's default CORS list would refuse its requests) and must stream from
``127.0.0.2`` too (a page told ``127.0.0.1`` would, on another machine, look for the data there).
Debian's headless ``chromium`` (software WebGL) opens the URL through ``playwright``; the test polls
screenshots until the 3D view shows the robots, judged by their colours (the mobile base's
assigned colour, the LIDAR hits), which no part of the static scene has. Every request the browser
makes is recorded: one to a host other than 127.0.0.2 (fonts, analytics, version checks, examples)
fails the test.
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

from urllib.parse import urlsplit

# Chromium's flags, the benchmarks' own: SwiftShader's software GL, and no page's renderer backgrounded nor its timers
# throttled (Chromium runs a background renderer at nice 5); the tests' own lists lacked those three
from robofabric.bench.viewer_web import CHROMIUM, CHROMIUM_ARGS
from robofabric.testing import free_port, robofabric_cmd, wait_until

VIEWPORT = {"width": 1280, "height": 800}
# Where the blueprint puts the 3D "world" view in a 1280x800 page (rerun-sdk 0.41, panels expanded).
WORLD_VIEW = (slice(int(0.09 * 800), int(0.71 * 800)), slice(int(0.17 * 1280), int(0.51 * 1280)))
ROBOT_PIXELS = 150


def robot_pixels(rgb: np.ndarray) -> int:
    """Pixels in robot colours: warm saturated (LIDAR hits, orange robots) or the blue of the second robot.

    The static scene (grey walls and floor, navy shelves, brown table, green markers) and the dark
    background have none: navy is too dull and its hue too far from the robot blue (tested below).
    """
    x = rgb[..., :3].astype(float) / 255.0
    r, g, b = x[..., 0], x[..., 1], x[..., 2]
    mx, mn = x.max(axis=-1), x.min(axis=-1)
    d = np.maximum(mx - mn, 1e-9)
    sat = np.where(mx > 0, (mx - mn) / np.maximum(mx, 1e-9), 0.0)
    hue = np.where(mx == r, ((g - b) / d) % 6, np.where(mx == g, (b - r) / d + 2, (r - g) / d + 4)) * 60.0
    warm = ((hue >= 340) | (hue <= 40)) & (sat > 0.7) & (mx > 0.35)
    blue = (hue >= 195) & (hue <= 215) & (sat > 0.7) & (mx > 0.45)
    return int((warm | blue).sum())


def _patch(rgb: tuple[int, int, int], shades=(0.6, 0.8, 1.0)) -> np.ndarray:
    return np.array([[[min(255, int(c * s)) for c in rgb] for s in shades]], dtype=np.uint8)


def test_robot_colour_classifier_sees_robots_and_not_the_scene():
    from user_peer.rerun_log import ROBOT_COLORS

    scene = [
        (179, 179, 179),
        (51, 89, 153),
        (140, 102, 64),
        (102, 76, 51),
        (40, 200, 80),
        (35, 35, 40),
        (120, 120, 125),
        (255, 255, 255),
    ]
    for c in scene:
        assert robot_pixels(_patch(c)) == 0, c
    for c in (ROBOT_COLORS[0], ROBOT_COLORS[1], (230, 40, 40)):
        assert robot_pixels(_patch(c)) == 3, c


@pytest.mark.slow
def test_served_web_viewer_shows_the_robots_from_another_address(router, world, procs, tmp_path):
    # a missing browser fails (a skip would hide it): .ci/run installs it, by hand `apt-get install chromium`
    assert Path(CHROMIUM).exists() and shutil.which("chromium"), (
        "Debian's chromium is not installed (apt-get install chromium)"
    )
    from playwright.sync_api import sync_playwright

    ep = f"tcp/127.0.0.1:{router[1]}"
    sim = procs.start(robofabric_cmd("sim", "--scene", "combined", "--world", world, "--connect", ep), name="sim")
    web, grpc = free_port(), free_port()
    view = procs.start(
        robofabric_cmd(
            "view",
            "--serve-web",
            "--advertise",
            "127.0.0.2",
            "--web-port",
            str(web),
            "--grpc-port",
            str(grpc),
            "--world",
            world,
            "--connect",
            ep,
        ),
        name="view",
    )
    found = wait_until(
        lambda: re.search(r"web viewer: open (http://\S+)", procs.output(view)),
        timeout=60,
        what="the viewer to print its URL",
        seen=lambda: procs.output(view)[-2000:],
    )
    url = found.group(1)
    assert url.startswith(f"http://127.0.0.2:{web}/?url=") and f"127.0.0.2%3A{grpc}%2Fproxy" in url, url
    assert sim.poll() is None, procs.output(sim)

    shot = tmp_path / "web-viewer.png"
    counts: list[int] = []
    requests: list[str] = []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport=VIEWPORT)
            page.on("request", lambda r: requests.append(r.url))
            page.goto(f"http://127.0.0.2:{web}/", timeout=120_000)  # the plain address: it leads to the live world
            assert f"url=rerun%2Bhttp%3A%2F%2F127.0.0.2%3A{grpc}%2Fproxy" in page.url, page.url
            cdp = page.context.new_cdp_session(page)
            deadline = time.monotonic() + 180
            while True:
                shot.write_bytes(base64.b64decode(cdp.send("Page.captureScreenshot", {"format": "png"})["data"]))
                rgb = np.asarray(Image.open(shot).convert("RGB"))
                counts.append(robot_pixels(rgb[WORLD_VIEW]))
                # done when the robots show and the page made the calls it meant for other hosts (analytics, the
                # version check), which must have come here (/_nonet/...)
                local_calls = {
                    h for h in ("tel.rerun.io", "api.github.com") if any(f"/_nonet/{h}" in u for u in requests)
                }
                if (counts[-1] >= ROBOT_PIXELS and len(local_calls) == 2) or time.monotonic() > deadline:
                    break
                page.wait_for_timeout(3000)
        finally:
            browser.close()
    keep = Path(__file__).resolve().parents[2] / "out" / "test-web-viewer.png"
    keep.parent.mkdir(exist_ok=True)
    shutil.copy(shot, keep)  # for a person to look at (out/ is ignored by git)
    assert counts[-1] >= ROBOT_PIXELS, f"robot-coloured pixels in the 3D view over time: {counts}; screenshot {keep}"
    assert view.poll() is None, procs.output(view)
    # nothing left the LAN: every request went to the viewer's own host (page, code, data, swallowed analytics)
    elsewhere = sorted(
        {u for u in requests if urlsplit(u).hostname != "127.0.0.2" and not u.startswith(("data:", "blob:"))}
    )
    assert not elsewhere, f"the page asked other hosts: {elsewhere}"
    assert any(f"127.0.0.2:{grpc}" in u for u in requests), requests  # and it streamed the world
