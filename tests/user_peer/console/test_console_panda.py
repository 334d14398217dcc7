"""A lab's own arm in the console, in a real browser: the Franka Panda (example-robot-data's URDF, 7 joints, made a
robot type by ``robots add``) in one world with the Meca500 and the base. A student logs in, takes the Panda,
moves it with a joint slider, drags the IK target in the 3D view and applies IK: the sim's flange reaches the
target. What the page did is read through the Python API, as an instructor would."""

from __future__ import annotations

import math
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

import robots
from robofabric.bench.viewer_web import CHROMIUM, CHROMIUM_ARGS  # no renderer backgrounded (test_console_browser.py)
from robofabric.testing import example_robot_urdf, free_port, robofabric_cmd, wait_until
from robots.urdf_import import install

from tests.user_peer.console.scene3d_probe import SCENE3D_JS, drag_sphere

pytestmark = pytest.mark.slow

OUT = Path(__file__).resolve().parents[3] / "out"
PANDA = "panda_description/urdf/panda.urdf"
PLACE = (1.5, -1.5)


def _message(page) -> str:
    return page.get_by_role("status").inner_text()


def _wait_message(page, pattern: str, timeout: float = 30.0) -> str:
    return wait_until(
        lambda: re.search(pattern, _message(page)) and _message(page),
        timeout=timeout,
        what=f"the page to say /{pattern}/",
        seen=lambda: _message(page),
    )


def test_a_student_drives_the_panda_from_the_console_slider_3d_drag_and_apply_ik(
    router, world, procs, tmp_path, monkeypatch
):
    import user_peer

    folder = tmp_path / "robots"
    install(example_robot_urdf(PANDA), into=folder, name="panda")
    monkeypatch.setenv(robots.description.ENV_PATH, str(folder))  # this process's user API, and its children
    assert Path(CHROMIUM).exists() and shutil.which("chromium"), (
        "Debian's chromium is not installed (apt-get install chromium)"
    )
    ep = f"tcp/127.0.0.1:{router[1]}"
    robot = f"panda:p1@{PLACE[0]},{PLACE[1]}"
    sim = procs.start(
        robofabric_cmd("sim", "--scene", "combined", "--robot", robot, "--world", world, "--connect", ep), name="sim"
    )
    procs.start(robofabric_cmd("compute", "--world", world, "--connect", ep), name="compute")
    web = free_port()
    console = procs.start(
        robofabric_cmd("console", "--world", world, "--connect", ep, "--listen", f"127.0.0.1:{web}"), name="console"
    )
    url = f"http://127.0.0.1:{web}/"
    wait_until(
        lambda: f"console: open {url}" in procs.output(console),
        timeout=90,
        what="the console's URL",
        seen=lambda: procs.output(console)[-2000:],
    )
    carol = user_peer.connect(world=world, connect=ep, user="carol", join_timeout=120)
    from playwright.sync_api import sync_playwright

    try:
        wait_until(
            lambda: carol.fabric.live_peers("compute"),
            timeout=120,
            what="the compute peer",
            seen=lambda: procs.output(sim)[-2000:],
        )
        p1, seen = carol.robot("p1"), carol.object("target")
        wait_until(lambda: p1.flange is not None and p1.joint_state is not None, timeout=60, what="the Panda's flange")
        assert len(p1.joint_state.q) == 7
        # a target the Panda reaches: 0.45 m ahead of its base (+x in the world), 0.5 m up
        seen.set_pose([PLACE[0] + 0.45, PLACE[1], 0.5])
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS)
            try:
                page = browser.new_context(viewport={"width": 1280, "height": 1350}).new_page()
                page.set_default_timeout(30_000)
                page.goto(url, timeout=60_000)
                # typed before the page's socket has shaken hands, the name and the click wait in timers of their own
                # and may be lost (a whole run: no world shown in 60 s); a student types after the page is up
                page.wait_for_function("() => window.did_handshake === true", timeout=60_000)
                page.get_by_label("Name").fill("dave")  # an open world: a name, no password
                page.get_by_role("button", name="Log in").click()
                wait_until(
                    lambda: page.get_by_text(f"world {world} · dave").is_visible(),
                    timeout=60,
                    what="dave's page to show his world",
                    seen=lambda: page.locator("body").inner_text()[-600:],
                )
                page.get_by_role("button", name="p1", exact=True).click()
                page.get_by_role("button", name="Request").click()
                _wait_message(page, r"request p1: you own it")
                page.get_by_text(re.compile(r"^arm p1 ")).wait_for()  # the Panda's panel, not the Meca500's
                # seven joint sliders, named after the URDF's joints, in its order
                OUT.mkdir(exist_ok=True)
                page.screenshot(path=str(OUT / "console-panda-owned.png"))

                def labels() -> list[str]:
                    sliders = page.get_by_role("slider")
                    return [sliders.nth(i).get_attribute("aria-label") or "" for i in range(sliders.count())]

                want = [f"J{j} (panda_joint{j}) degrees" for j in range(1, 8)]
                wait_until(
                    lambda: [x for x in labels() if x.startswith("J")] == want,
                    timeout=30,
                    what="the Panda's seven joint sliders",
                    seen=labels,
                )

                # a slider: J1 to its right end moves the sim's J1 there (its upper limit, 2.8973 rad)
                q0 = np.asarray(p1.joint_state.q, dtype=float)
                j1 = page.get_by_role("slider", name="J1 (panda_joint1) degrees")
                box = j1.bounding_box()
                j1.click(position={"x": box["width"] - 1, "y": box["height"] / 2})
                wait_until(
                    lambda: p1.joint_state.q[0] >= 2.85 and np.max(np.abs(p1.joint_state.dq)) < 1e-3,
                    timeout=60,
                    what="the Panda's J1 at its upper limit, still",
                    seen=lambda: (q0, p1.joint_state.q),
                )

                # the 3D view draws the Panda's links at its live joints, and its target
                def drawn() -> dict | None:
                    out = page.evaluate(SCENE3D_JS)
                    return out if out and out.get("target") and len(out["ends"]) >= 14 else None

                wait_until(
                    drawn,
                    timeout=60,
                    what="the 3D view with the Panda's links and the target",
                    seen=lambda: page.evaluate(SCENE3D_JS),
                )
                flange = np.asarray(p1.flange.position)  # still: J1 stopped at its limit
                wait_until(
                    lambda: min(math.dist(e, flange) for e in drawn()["ends"]) <= 0.005,
                    timeout=20,
                    what="the 3D Panda's last link ending at the flange the sim reports",
                    seen=lambda: (min(math.dist(e, flange) for e in drawn()["ends"]), flange),
                )
                before = np.asarray(seen.pose.position, dtype=float)
                wait_until(
                    lambda: (s := drawn()) and math.dist(s["target"], before) <= 1e-4,
                    timeout=20,
                    what="the sphere at the target",
                )
                drag_sphere(page, drawn()["screen"])
                wait_until(
                    lambda: np.linalg.norm(np.asarray(seen.pose.position)[:2] - before[:2]) >= 0.005,
                    timeout=20,
                    what="the target dragged (read through the Python API)",
                    seen=lambda: (before, seen.pose.position),
                )
                target = np.asarray(seen.pose.position, dtype=float)
                assert target[2] == pytest.approx(before[2], abs=1e-6) and np.linalg.norm(target - before) <= 0.1
                ik = page.get_by_text(re.compile(r"^IK: "))
                wait_until(
                    lambda: ik.inner_text().startswith("IK: ["), timeout=60, what="the IK solution", seen=ik.inner_text
                )
                OUT.mkdir(exist_ok=True)
                page.screenshot(path=str(OUT / "console-panda-dragged.png"))
                page.get_by_role("button", name="Apply IK").click()
                _wait_message(page, r"apply IK .*: ok", timeout=60)

                def on_target() -> tuple[float, int] | None:
                    p = p1.flange
                    err = float(np.linalg.norm(np.asarray(p.position) - target)) if p is not None else math.inf
                    return (err, p.header.seq) if err <= 1e-3 else None

                first = wait_until(
                    on_target,
                    timeout=60,
                    what="the Panda's flange at the dragged target",
                    seen=lambda: (p1.flange, target),
                )
                wait_until(
                    lambda: (o := on_target()) is not None and o[1] >= first[1] + 20,
                    timeout=30,
                    what="the Panda's flange to stay at the target",
                    seen=lambda: (p1.flange, target),
                )
                page.screenshot(path=str(OUT / "console-panda-reached.png"))
                page.get_by_role("button", name="Release").click()
                _wait_message(page, r"release p1: ok")
            finally:
                browser.close()
    finally:
        carol.close()
