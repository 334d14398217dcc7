"""``robofabric console`` in a real browser: students log in with their own passwords in a ``secure init`` world.

One class per module: a router with the class's logins, the sim (scene combined) and the compute peer
under their own logins, and the console process with no login of its own. Debian's chromium, through
playwright, plays alice's and bob's pages; carol (an instructor) reads the world through the Python
API to check what the pages did. Every request a page makes is recorded: one to a host other than the
console server fails the offline test. Screenshots are kept in out/ for a person to look at.
"""

from __future__ import annotations

import json
import math
import re
import shutil
import time
import uuid
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import urlsplit

import numpy as np
import pytest
import zenoh

from fabric.text import one_line
from fabric import keys
from fabric.interfaces import Command, EventKind, OwnershipRecord
from robofabric.secure import init

# Chromium's flags, the benchmarks' own: SwiftShader's software GL, and no page's renderer backgrounded nor its timers
# throttled (Chromium runs a background renderer at nice 5); the tests' own lists lacked those three
from robofabric.bench.viewer_web import CHROMIUM, CHROMIUM_ARGS
from robofabric.testing import ProcessGroup, free_port, robofabric_cmd, wait_until
from user_peer.console.server import RECONNECT_S
from user_peer.console.world_kind import login_caption

from tests.user_peer.console.scene3d_probe import SCENE3D_JS, drag_sphere

# 600 s a test: a page's actions wait up to 120 s each (open_page), and a test that sets up again after a page that
# dropped its connection does it twice or three times; their own waits say what failed, this is the backstop
pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]

VIEWPORT = {"width": 1280, "height": 1350}
GRACE_S = 30.0
"""The class console's grace (`--grace`; the console's default is 10 s). A reloaded page comes back within it, its
ticket read from the tab by a round trip to the page: with 3 s, at load 15 the page before the reload was gone and
the grace over before that read came back (CI and run 11, 2026-12-01); with 10 s, beside whole runs at load 20-25 a
page reloaded past its reconnect window took longer to load again, and came back at its login card ("Your session
ended": CI of 4e1c021, and the page-closes test beside runs 15 and 17, twice in a row in one of them)."""
OUT = Path(__file__).resolve().parents[3] / "out"


@dataclass
class Klass:
    world: str
    url: str
    host: str
    passwords: dict[str, str]
    carol: object  # user_peer.World of the instructor: reads what the pages did
    procs: ProcessGroup
    console: object
    cards: dict = field(default_factory=dict)  # each person's login card (robofabric/login_cards.py)


def _password(path: Path) -> str:
    return json.loads(zenoh.Config.from_file(str(path)).get_json("transport/auth/usrpwd/password"))


@pytest.fixture(scope="module")
def klass(tmp_path_factory):
    import user_peer

    tmp = tmp_path_factory.mktemp("console")
    world = f"c{uuid.uuid4().hex[:8]}"
    ep = f"tcp/127.0.0.1:{free_port()}"
    d = tmp / "class"
    made = init(d, users=["alice", "bob", "dave"], instructors=["carol"], listen=[ep])
    files = made.clients
    with ProcessGroup(tmp) as procs:
        router = procs.start(robofabric_cmd("router", "--zenoh-config", str(d / "router.json5")), name="router")
        wait_until(
            lambda: "listening" in procs.output(router), timeout=30, what="router", seen=lambda: procs.output(router)
        )
        sim = procs.start(
            robofabric_cmd("sim", "--scene", "combined", "--world", world, "--zenoh-config", str(files["sim"])),
            name="sim",
        )
        procs.start(
            robofabric_cmd("compute", "--world", world, "--zenoh-config", str(files["compute"])), name="compute"
        )
        web = free_port()
        console = procs.start(
            robofabric_cmd(
                "console",
                "--world",
                world,
                "--connect",
                ep,
                "--listen",
                f"127.0.0.1:{web}",
                "--grace",
                str(GRACE_S),
                "--instructors",
                "carol",
                # the 3D view drawn 2 times a second, not 10: Chromium draws it in software GL, and two pages at 10
                # took most of this box (a page driving: 1.10 of a core at 10, 0.64 at 2, `robofabric bench console
                # --pages 1 --seconds 15 --swiftshader --view-fps 10` and `2`, docs/console.md)
                "--view-fps",
                "2",
            ),
            name="console",
        )
        url = f"http://127.0.0.1:{web}/"
        wait_until(
            lambda: f"console: open {url}" in procs.output(console),
            timeout=60,
            what="the console's URL",
            seen=lambda: procs.output(console)[-2000:],
        )
        carol = user_peer.connect(world=world, zenoh_config=str(files["carol"]), join_timeout=120)
        try:
            wait_until(
                lambda: carol.fabric.live_peers("compute"),
                timeout=120,
                what="the compute peer",
                seen=lambda: procs.output(sim)[-2000:],
            )
            yield Klass(
                world,
                url,
                f"127.0.0.1:{web}",
                {n: _password(files[n]) for n in ("alice", "bob", "dave", "carol")},
                carol,
                procs,
                console,
                made.cards,
            )
        finally:
            carol.close()


@pytest.fixture(scope="module")
def browser():
    assert Path(CHROMIUM).exists() and shutil.which("chromium"), (
        "Debian's chromium is not installed (apt-get install chromium)"
    )
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS)
        try:
            yield b
        finally:
            b.close()


REQUESTS: list[str] = []  # every request any page of this module made
CONTEXTS: list = []  # the browser contexts the running test opened


@pytest.fixture(autouse=True)
def _pages_close_after_each_test():
    """Every page a test opened closes when it ends, passed or failed: a page left open by a failed test drew on
    in the browser's one GPU process (its 3D view at 10 fps in software GL) and starved the next tests' pages, so
    on a loaded box one failure became a row of them (playwright waiting for a Log in button to be 'stable')."""
    yield
    while CONTEXTS:
        ctx = CONTEXTS.pop()
        try:
            ctx.close()
        except Exception:  # closed by the test already, or the browser went
            pass


@pytest.fixture(autouse=True)
def _robots_free_after_each_test(klass):
    """Every robot a student holds when a test ends is taken back (the instructor's staff action), passed or failed:
    a test that failed with bob holding arm1 (CI, stop 59) failed two after it that asked for arm1 or showed it."""
    yield
    for r in klass.carol.info().robots:
        rec = klass.carol.ownership.record(r.id)
        for _ in range(3):  # a take-back hands the robot to the next in its queue, if any
            if rec is None or not rec.owner or rec.policy != "exclusive":
                break
            out = klass.carol.ownership.client.staff(r.id, "take_back", timeout=10.0)
            assert out.outcome == "done" or "nobody to take it back" in out.reason, (r.id, out)
            rec = out.record
        assert rec is None or not rec.owner or rec.policy != "exclusive", f"{r.id} held after three take-backs: {rec}"


def new_context(browser, **kw):
    ctx = browser.new_context(**kw)
    CONTEXTS.append(ctx)
    return ctx


# Clicks do not wait on navigations (``no_wait_after``): the page is one NiceGUI page that never navigates on a
# click, but NiceGUI reloads a page whose connection timed out, and at load a click that met such a reload waited
# 30 s for it and failed (CI, 2026-11-30: bob's Queue; beside two CPU hogs: base1's button). What each click
# does is then waited on through the page's state, as every test here already does. Log out reloads on purpose.


def open_page(browser, klass: Klass):
    page = new_context(browser, viewport=VIEWPORT).new_page()
    page.on("request", lambda r: REQUESTS.append(r.url))
    lines: list[str] = []
    page.on("console", lambda m: lines.append(m.text))  # NiceGUI says there why it reloads a page
    PAGE_LOGS[id(page)] = lines
    # 120 s for an action: at the suite's load (15-35 on two cores) a page's renderer, drawing its 3D view in software
    # GL, once took over 30 s to hit-test a visible, enabled, stable button (CI run of 2026-11-30, bob's Request);
    # a page whose pings went unanswered 20 s is reloaded by NiceGUI, and a click then waits for the page to load
    # again and resume her session: past 60 s in a whole run at load 10-17 (bob's base1, then his Request)
    page.set_default_timeout(120_000)
    page.goto(klass.url, timeout=60_000)
    # typed before the page's socket has shaken hands, a field's value and the Log in click wait in timers of their
    # own, and the click may go first: bob's login once came with no name ("name must not be empty", a whole run
    # beside a CPU hog, load 15). A student types after the page is up; so does the test
    page.wait_for_function("() => window.did_handshake === true", timeout=60_000)
    return page


PAGE_LOGS: dict[int, list[str]] = {}  # each page's browser console, shown when a wait on it fails
PAGE_USERS: dict[int, tuple["Klass", str]] = {}  # who logged in on each page (the class, her name)
SELECTED: dict[int, str] = {}  # the robot each page selected last (select_robot)


def back_in(page) -> bool:
    """Where ``page`` is back at its login card, she logs in again (and selects her robot again), as a student
    would, said in the test's output; True if she had to. A page whose socket was down past the reconnect window at
    load is reloaded, and one that took longer than the grace to come back has lost its session (beside whole runs,
    2026-12-02: bob's base1 three times in three, his Request in run 16)."""
    if id(page) not in PAGE_USERS or not page.get_by_role("button", name="Log in").is_visible():
        return False
    klass, name = PAGE_USERS[id(page)]
    print(f"{name}'s page came back at its login card: she logs in again", flush=True)
    logged_in(page, klass, name)
    if id(page) in SELECTED:
        select_robot(page, klass, name, SELECTED[id(page)])
    return True


def log_in(page, name: str, password: str) -> None:
    page.get_by_label("Name").fill(name)
    page.get_by_label("Password").fill(password)
    page.get_by_role("button", name="Log in").click(no_wait_after=True)


def select_robot(page, klass: Klass, name: str, robot: str) -> None:
    """``name`` clicks ``robot``'s button (kept for :func:`back_in`); where a reload swallowed the click and her page
    came back at its login card, she logs in again and clicks again, as :func:`back_in` says."""
    from playwright.sync_api import TimeoutError as PlaywrightTimeoutError

    SELECTED[id(page)] = robot
    for attempt in (1, 2):
        try:
            page.get_by_role("button", name=robot, exact=True).click(no_wait_after=True, timeout=60_000)
            return
        except PlaywrightTimeoutError:
            body = one_line(page.locator("body").inner_text(timeout=30_000), 300)
            if attempt == 2 or not page.get_by_role("button", name="Log in").is_visible():
                raise AssertionError(f"{name}'s {robot} not clickable in 60 s; her page shows {body!r}") from None
            print(f"{name}'s page came back at its login card ({body!r}): she logs in again")
            logged_in(page, klass, name)


def logged_in(page, klass: Klass, name: str) -> None:
    from playwright.sync_api import TimeoutError as PlaywrightTimeoutError

    PAGE_USERS[id(page)] = (klass, name)
    log_in(page, name, klass.passwords[name])
    try:
        page.get_by_text(f"world {klass.world} · {name}").wait_for(timeout=120_000)
    except PlaywrightTimeoutError:
        raise AssertionError(
            f"{name}'s page never showed her world in 120 s; it says: "
            f"{one_line(page.locator('body').inner_text(), 600)!r}"
        ) from None


def shot(page, name: str) -> Path:
    """The page as a person sees it, kept for a look (no assertion reads it). Drawing a WebGL page in software on
    a loaded box once took past 120 s (run 5 of 2026-12-01, load 20) and failed a test whose page did all it was
    asked: a shot not taken in 60 s is said as a warning, and the test goes on judging the page by its DOM."""
    from playwright.sync_api import TimeoutError as PlaywrightTimeoutError

    OUT.mkdir(exist_ok=True)
    path = OUT / f"console-{name}.png"
    try:
        page.screenshot(path=str(path), timeout=60_000)
    except PlaywrightTimeoutError:
        warnings.warn(f"screenshot {path.name}: not taken in 60 s (a loaded box drawing in software)", stacklevel=2)
    return path


def message(page) -> str:
    return page.get_by_role("status").inner_text()


def status_now(page) -> str:
    """The page's status line, or what the page shows where it has none within 10 s (its login card, a page
    reloading): a wait on a message polls this, and fails at its own deadline saying what was there instead of
    waiting on the element 120 s (CI, 2026-12-02: bob's Queue, no status for 120 s, nothing said of why)."""
    from playwright.sync_api import TimeoutError as PlaywrightTimeoutError

    try:
        return page.get_by_role("status").inner_text(timeout=10_000)
    except PlaywrightTimeoutError:
        try:
            body = one_line(page.locator("body").inner_text(timeout=5_000), 300)
        except PlaywrightTimeoutError:
            body = "(the page's body not read in 5 s)"
        return f"(no status line in 10 s; the page shows: {body!r})"


def wait_message(page, pattern: str, timeout: float = 30.0) -> str:
    return wait_until(
        lambda: re.search(pattern, said := status_now(page)) and said,
        timeout=timeout,
        what=f"the page to say /{pattern}/",
        seen=lambda: (status_now(page), _socket_state(page), PAGE_LOGS.get(id(page), [])[-10:]),
    )


def press(page, button, pattern: str, timeout: float = 30.0) -> str:
    """Click ``button`` and wait for the page to say ``pattern``. A click made while the page's socket is down never
    reaches the console (the page says it is reconnecting): as a student would, it is made again once the socket is
    back, twice at most (run 6 of 2026-12-01 at load 20: bob's Request, his socket down through the 30 s wait)."""
    from playwright.sync_api import TimeoutError as PlaywrightTimeoutError

    for tries in range(3):
        back_in(page)
        wait_until(
            lambda: _socket_state(page) == "socket connected",
            timeout=60,
            interval=0.2,
            what="the page's socket connected",
            seen=lambda: (_socket_state(page), PAGE_LOGS.get(id(page), [])[-10:]),
        )
        wait_until(
            lambda: page.get_by_role("status").count() > 0,
            timeout=120,
            interval=0.2,
            what="the page's status line (a reloaded page's: she is kept logged in)",
            seen=lambda: one_line(page.locator("body").inner_text(), 300),
        )
        down: list[str] = []
        try:
            button.click(no_wait_after=True, timeout=60_000)
        except PlaywrightTimeoutError:  # a reload swallowed it: clicked again, once she is back in where she must be
            if tries == 2:
                raise
            print(f"the click found no button in 60 s (the page reloaded?): clicked again ({tries + 1})")
            continue

        def said() -> str | None:
            try:  # a page NiceGUI reloads (its socket gone past the reconnect window) has no status for a while
                text = page.get_by_role("status").inner_text(timeout=2_000)
            except PlaywrightTimeoutError:
                try:
                    body = one_line(page.locator("body").inner_text(timeout=5_000), 200)
                except PlaywrightTimeoutError:
                    body = "(no body in 5 s)"
                down.append("no status: " + body)
                return None
            if _socket_state(page) != "socket connected":
                down.append(text)
            return text if re.search(pattern, text) else None

        try:
            return wait_until(
                said,
                timeout=timeout,
                interval=0.2,
                what=f"the page to say /{pattern}/",
                seen=lambda: (down[-3:], _socket_state(page), PAGE_LOGS.get(id(page), [])[-10:]),
            )
        except AssertionError:
            if not down or tries == 2:
                raise
            print(f"the page's socket went down after the click ({len(down)} looks); clicked again once it is back")
    raise AssertionError("unreachable")


def _socket_state(page) -> str:
    """Whether the page's socket to the console is connected now: a page that lost it shows what it last heard (a
    reload test's page said "WORLD GONE" for 30 s while the console counted no page connected, load 17)."""
    try:
        return str(
            page.evaluate(
                "() => window.socket === undefined ? 'no socket' : window.socket.connected ? 'socket connected' "
                ": 'socket not connected'"
            )
        )
    except Exception as exc:  # the page closed or is navigating: say that instead
        return f"socket state unknown ({type(exc).__name__})"


def target_label(page) -> np.ndarray:
    text = page.get_by_text(re.compile(r"^\(-?[0-9.]+, -?[0-9.]+, -?[0-9.]+\) m$")).inner_text()
    return np.array([float(v) for v in text.strip("() m").split(",")])


def nudge(page, buttons: tuple[str, ...], step: float = 0.01) -> np.ndarray:
    """Press the nudge buttons; returns the target once the page shows it moved and the IK solution for it."""
    start = target_label(page)
    want = start.copy()
    for name in buttons:
        page.get_by_role("button", name=name).click(no_wait_after=True)
        want["xyz".index(name[0])] += step if name.endswith("plus") else -step
    wait_until(
        lambda: np.allclose(target_label(page), want, atol=5e-4),
        timeout=10,
        what=f"the target at {want}",
        seen=lambda: target_label(page),
    )
    ik = page.get_by_text(re.compile(r"^IK: "))
    wait_until(lambda: ik.inner_text().startswith("IK: ["), timeout=30, what="the IK solution", seen=ik.inner_text)
    return want


def test_a_from_the_page_and_bob_sees_alice_own_the_arm(browser, klass):
    alice = open_page(browser, klass)
    logged_in(alice, klass, "alice")
    alice.get_by_role("button", name="arm1", exact=True).click(no_wait_after=True)
    alice.get_by_role("button", name="Request").click(no_wait_after=True)
    wait_message(alice, r"request arm1: you own it")
    apply = alice.get_by_role("button", name="Apply IK")
    wait_until(lambda: apply.is_enabled(), timeout=10, what="Apply IK enabled for the owner")
    target = nudge(alice, ("z minus", "z minus", "x minus"))
    seen = klass.carol.object("target")
    wait_until(
        lambda: seen.pose is not None and np.allclose(seen.pose.position, target, atol=1e-6),
        timeout=10,
        what="the target where alice's page put it (read through the Python API)",
        seen=lambda: seen.pose,
    )
    apply.click(no_wait_after=True)
    wait_message(alice, r"apply IK .*: ok")
    arm = klass.carol.robot("arm1")

    def error() -> float | None:
        p, js = arm.flange, arm.joint_state
        if p is None or js is None or np.max(np.abs(js.dq)) > 1e-3:
            return None
        err = float(np.linalg.norm(np.asarray(p.position) - target))
        return err if err <= 1e-3 else None

    err = wait_until(
        error,
        timeout=30,
        what="arm1's flange at the target (read through the Python API)",
        seen=lambda: (arm.flange, target, alice.get_by_text(re.compile(r"^IK: ")).inner_text()),
    )
    assert err <= 1e-3
    shot(alice, "alice-test-a")

    bob = open_page(browser, klass)
    logged_in(bob, klass, "bob")
    row = bob.get_by_text(re.compile(r"^arm · owner: alice"))
    row.wait_for()
    assert bob.get_by_text(re.compile(r"^arm arm1 .* owner: alice · controls disabled")).is_visible()
    for name in ("Apply IK", "Stop", "Reset", "z plus"):
        assert bob.get_by_role("button", name=name, exact=True).is_disabled(), name
    assert bob.get_by_role("slider", name=re.compile("^J1")).get_attribute("aria-disabled") == "true"
    shot(bob, "bob-sees-alice")

    # takeover: while alice's arm moves (slowly: speed at its minimum, J1 to its end), bob is refused, with the reason
    speed = alice.get_by_role("slider", name="Speed scale")
    box = speed.bounding_box()
    speed.click(no_wait_after=True, position={"x": 1, "y": box["height"] / 2})  # its left end: the minimum
    wait_until(
        lambda: speed.get_attribute("aria-valuenow") == "0.05",
        timeout=5,
        what="the speed slider at its minimum",
        seen=lambda: speed.get_attribute("aria-valuenow"),
    )
    j1 = alice.get_by_role("slider", name=re.compile("^J1"))
    box = j1.bounding_box()
    records: list = []  # arm1's records as the authority publishes them (on each change of owner, epoch or motion)
    watch = klass.carol.fabric.subscribe(
        keys.own(klass.world, "arm1"), lambda _k, r: records.append(r), expected=OwnershipRecord
    )
    refused = r"arm1 is moving and belongs to alice: wait until it stops, or press Queue to be next"
    try:
        for attempt in range(3):  # J1 to one end, then the other: ~20 s at the minimum speed
            x = box["width"] - 1 if attempt % 2 == 0 else 1
            j1.click(no_wait_after=True, position={"x": x, "y": box["height"] / 2})
            wait_until(
                lambda: arm.record is not None and arm.record.state == "moving",
                timeout=10,
                what="arm1 moving",
                seen=lambda: arm.record,
            )
            # arm1 is selected (the first robot)
            text = press(bob, bob.get_by_role("button", name="Request"), rf"request arm1: ({refused}|you own it)")
            if re.search(refused, text):
                break
            # granted: lawful only if the authority had seen the arm stop first (a starved sim holds its robots: CI
            # once gave bob the arm at epoch 2, moving a moment before); then alice takes it back and moves it again
            (mine,) = wait_until(
                lambda: next(((i,) for i, r in enumerate(records) if r.owner == "bob"), None),
                timeout=10,
                what="bob's grant of arm1 among its records",
                seen=lambda: records,
            )
            # lawful after a still arm of alice's, or a free one: alice's hold ended first (CI, load 6-12: her page
            # reloaded, her arm was free at epoch 5, and bob's Request had it at 6)
            before = records[mine - 1] if mine > 0 else None
            assert before is not None and (
                before.owner == "" or (before.owner == "alice" and before.state == "still")
            ), (records, text)
            why = "free" if before.owner == "" else "stopped"
            print(f"attempt {attempt}: arm1 {why} before bob asked ({before}); alice takes it back")
            press(bob, bob.get_by_role("button", name="Release"), r"release arm1: ok")
            press(alice, alice.get_by_role("button", name="Request"), r"request arm1: you own it")
            records.clear()
        else:
            raise AssertionError(f"arm1 stopped before bob asked, three times: {text}")
    finally:
        watch.undeclare()
    assert "[NotOwner: " in text and "in motion" in text, text  # the next step in plain words, the code's reason after
    shot(bob, "bob-refused")
    # alice stops it; still, it is bob's for the asking: alice's page then shows her controls disabled
    alice.get_by_role("button", name="Stop", exact=True).click(no_wait_after=True)
    wait_until(lambda: arm.record.state == "still", timeout=30, what="arm1 still", seen=lambda: arm.record)
    bob.get_by_role("button", name="Request").click(no_wait_after=True)
    wait_message(bob, r"request arm1: you own it")
    alice.get_by_text(re.compile(r"^arm arm1 .* owner: bob · controls disabled")).wait_for()
    assert apply.is_disabled()
    bob.get_by_role("button", name="Release").click(no_wait_after=True)
    wait_message(bob, r"release arm1: ok")
    alice.context.close()
    bob.context.close()


def _svg_points(page, selector: str) -> list[tuple[float, float]]:
    text = page.locator(selector).first.get_attribute("points")
    return [tuple(float(v) for v in p.split(",")) for p in text.split()]


def _center(page, selector: str) -> tuple[float, float]:
    """The centre of the view's shape on the screen (the view redraws 5 times a second: a shape between two draws
    has no box, and is far away)."""
    box = page.locator(selector).first.bounding_box()
    return (box["x"] + box["width"] / 2, box["y"] + box["height"] / 2) if box else (math.inf, math.inf)


def test_dragging_the_ik_target_on_the_view_moves_it_and_the_arm_is_drawn_link_by_link(browser, klass):
    """A press on the IK target and a release elsewhere on the view move the scene's target there, its height
    kept (read through the Python API), and the page shows it there; the followed arm is drawn as its chain of
    joints, ending at the flange the sim reports."""
    from user_peer.console.state import scene_layout
    from user_peer.console.topview import PX_PER_M

    bob = open_page(browser, klass)
    logged_in(bob, klass, "bob")
    target_svg = 'svg circle[fill="#f59f00"]'
    bob.locator(target_svg).wait_for(state="attached")
    seen = klass.carol.object("target")
    before = target_label(bob)  # where the page has it (the scene's, or where test A left it)
    view = bob.get_by_label(re.compile("^Live view"))
    view.scroll_into_view_if_needed()  # the map's row is under the arm's while the arm is selected
    natural_js = "() => document.querySelector('img').naturalWidth"
    wait_until(lambda: bob.evaluate(natural_js) > 0, timeout=10, what="the view's picture, fetched from the console")
    natural = bob.evaluate(natural_js)
    m_per_screen_px = natural / view.bounding_box()["width"] / PX_PER_M
    x0, y0 = _center(bob, target_svg)
    dx, dy = 60, -40  # screen pixels: right and up, so +x and +y in the world
    bob.mouse.move(x0, y0)
    bob.mouse.down()
    bob.mouse.move(x0 + dx / 2, y0 + dy / 2)
    bob.mouse.move(x0 + dx, y0 + dy)
    bob.mouse.up()
    want = before + np.array([dx * m_per_screen_px, -dy * m_per_screen_px, 0.0])
    wait_until(
        lambda: seen.pose is not None and np.allclose(seen.pose.position, want, atol=0.01),
        timeout=10,
        what=f"the target dragged to {want} (read through the Python API)",
        seen=lambda: (before, seen.pose.position),
    )
    assert seen.pose.position[2] == pytest.approx(before[2], abs=1e-3)  # a drag from above keeps the height
    wait_until(
        lambda: math.dist(_center(bob, target_svg), (x0 + dx, y0 + dy)) <= 2.0,
        timeout=10,
        what="the page drawing the target where it was dropped",
        seen=lambda: (_center(bob, target_svg), (x0 + dx, y0 + dy)),
    )
    assert "goal" not in message(bob)  # the click that ended the drag placed no goal
    assert np.allclose(target_label(bob), seen.pose.position, atol=5e-4)

    frame, _ = scene_layout(klass.carol.info())
    arm = klass.carol.robot("arm1")
    links = bob.locator("svg polyline.rf-arm-links")
    links.first.wait_for(state="attached")
    pts = _svg_points(bob, "svg polyline.rf-arm-links")
    assert len(pts) == 8  # the base, then the Meca500's six joints and its flange frame
    flange = frame.px(float(arm.flange.position[0]), float(arm.flange.position[1]))
    assert math.dist(pts[-1], flange) <= 1.0, (pts[-1], flange)  # 1 image pixel: 2.5 cm at 40 px/m
    shot(bob, "bob-drag")
    bob.context.close()


def test_holding_up_drives_the_base_and_releasing_stops_it(browser, klass):
    base = klass.carol.robot("base1")
    bob = open_page(browser, klass)
    logged_in(bob, klass, "bob")
    bob.get_by_role("button", name="base1", exact=True).click(no_wait_after=True)
    bob.get_by_role("button", name="Request").click(no_wait_after=True)
    wait_message(bob, r"request base1: you own it")
    bob.locator("body").click(no_wait_after=True, position={"x": 5, "y": 5})  # focus on the page, not on a control

    def speed() -> float:
        p = base.pose
        return math.hypot(p.linear[0], p.linear[1]) if p is not None else 0.0

    start = base.xy_theta
    poses: list = []
    sub = base.on("pose", lambda _k, p: poses.append(p))
    twists: list = []  # (arrival, Command) of bob's twists to base1, as the wire carries them
    cmds = klass.carol.fabric.subscribe(
        keys.robot_cmd(klass.world, "base1", "twist", "bob"),
        lambda _k, c: twists.append((time.time_ns(), c)),
        expected=Command,
    )
    bob.keyboard.down("ArrowUp")
    try:
        wait_until(
            lambda: speed() > 0.1, timeout=10, what="base1 moving while ↑ is held", seen=lambda: (speed(), message(bob))
        )
        bob.wait_for_timeout(1500)  # held for longer than the sim's twist deadman: the page refreshes it
        assert speed() > 0.1, speed()
    finally:
        released = time.time_ns()
        bob.keyboard.up("ArrowUp")
    # the page's own stop: a zero twist on the wire after the release (the sim's twist deadman would stop the base
    # too, with nothing sent; timing the braking cannot tell them apart on a loaded machine)
    wait_until(
        lambda: any(t > released and c.body.v == 0 and c.body.omega == 0 for t, c in twists),
        timeout=5,
        what="the page's zero twist after the release",
        seen=lambda: [(t > released, c.body) for t, c in twists[-3:]],
    )
    wait_until(lambda: speed() < 0.02, timeout=5, what="base1 to stop after ↑ was released", seen=speed)
    # and in this subscription's own list, read below: its callback can come after the handle's (a run at load 15-24:
    # no still pose in it yet when it was closed)
    wait_until(
        lambda: any(p.header.wall_ns > released and math.hypot(p.linear[0], p.linear[1]) < 0.02 for p in poses),
        timeout=10,
        what="a still pose of base1 in the test's subscription",
    )
    sub.close()
    cmds.undeclare()
    # when the sim saw it still (its pose's wall clock, this host's): the test process's own delays (playwright,
    # this subscription) do not count
    after = [p for p in poses if p.header.wall_ns > released]
    cruise = max(math.hypot(p.linear[0], p.linear[1]) for p in poses if p.header.wall_ns <= released)
    braking = next(p for p in after if math.hypot(p.linear[0], p.linear[1]) < 0.9 * cruise)
    still = next(p for p in after if math.hypot(p.linear[0], p.linear[1]) < 0.02)
    braked, stopped = (braking.header.wall_ns - released) / 1e9, (still.header.wall_ns - released) / 1e9
    print(f"base1 braking {braked:.3f} s and still {stopped:.3f} s after the key was released (the sim's pose stamps)")
    moved = math.hypot(base.xy_theta[0] - start[0], base.xy_theta[1] - start[1])
    shot(bob, "bob-drove")
    assert moved > 0.2, moved
    # how soon is the console benchmark's to measure (0.2-0.3 s on a quiet machine, 0.4-0.55 s seen at load 20-30);
    # here only that it braked from cruise to rest once the key was up
    assert 0 < braked <= stopped, (braked, stopped)
    bob.get_by_role("button", name="Release").click(no_wait_after=True)
    wait_message(bob, r"release base1: ok")
    # the page follows in full only the robots it shows: the arm, not selected and not hers, was let go of; once
    # she selects it, it is followed and the base she released, no longer selected, is let go of
    # (a panel shows only while its robot is selected or hers: the one not selected is there, hidden)
    arm_title = bob.get_by_text(re.compile(r"^arm arm1 .* · click arm1 to follow its joints$"))
    wait_until(  # 30 s: at load 20 the page was told its base's release and no more for 10 s (run 6 of 2026-12-01)
        lambda: arm_title.count() > 0,
        timeout=30,
        interval=0.2,
        what="arm1's title saying it is not followed",
        seen=lambda: (message(bob), _socket_state(bob), PAGE_LOGS.get(id(bob), [])[-10:]),
    )
    assert not arm_title.is_visible()
    bob.get_by_role("button", name="arm1", exact=True).click(no_wait_after=True)
    bob.get_by_text(re.compile(r"^arm arm1 .* owner: [^·]+ · controls disabled$")).wait_for(timeout=30_000)
    pose = bob.get_by_text(re.compile(r"^pose: click base1 to follow it"))
    pose.wait_for(state="attached", timeout=30_000)
    assert not pose.is_visible()
    shot(bob, "bob-follows-the-arm")
    bob.context.close()


def test_b_from_the_page_map_goal_plan_follow(browser, klass):
    from user_peer.console.state import scene_layout

    base = klass.carol.robot("base1")
    bob = open_page(browser, klass)
    logged_in(bob, klass, "bob")
    bob.get_by_role("button", name="base1", exact=True).click(no_wait_after=True)
    bob.get_by_role("button", name="Request").click(no_wait_after=True)
    wait_message(bob, r"request base1: you own it")
    bob.get_by_role("button", name="Build map").click(
        no_wait_after=True
    )  # starts mapping (and builds what the scans saw so far)
    wait_message(bob, r"build map: \d+ x \d+ cells", timeout=60)
    # turn in place at speed 3 while the compute peer maps, as the paper's Test B drives
    bob.locator("body").click(no_wait_after=True, position={"x": 5, "y": 5})
    bob.keyboard.press("3")
    bob.keyboard.down("ArrowLeft")
    bob.wait_for_timeout(5000)
    bob.keyboard.up("ArrowLeft")
    wait_until(lambda: base.pose is not None and abs(base.pose.angular[2]) < 0.05, timeout=10, what="base1 still")
    bob.get_by_role("button", name="Build map").click(no_wait_after=True)
    wait_message(bob, r"build map: \d+ x \d+ cells", timeout=60)
    # the goal, clicked on the map where the page draws (-2.5, 0.5): the page's own frame, scaled to the picture
    goal = (-2.5, 0.5)
    frame, _ = scene_layout(klass.carol.info())
    img = bob.get_by_label(re.compile("^Live view")).locator("img").first
    box = img.bounding_box()
    px, py = frame.px(*goal)
    img.click(
        no_wait_after=True, position={"x": px * box["width"] / frame.width, "y": py * box["height"] / frame.height}
    )
    wait_message(bob, r"goal at \(-2\.\d\d, 0\.\d\d\)")
    bob.get_by_role("button", name="Plan").click(no_wait_after=True)
    wait_message(bob, r"plan \(hybrid_astar\): \d+ poses", timeout=60)
    bob.get_by_role("button", name="Follow").click(no_wait_after=True)
    wait_message(bob, r"follow base1: ok")

    def arrived() -> float | None:
        p = base.pose
        if p is None or math.hypot(p.linear[0], p.linear[1]) > 0.01 or abs(p.angular[2]) > 0.02:
            return None
        d = math.hypot(p.position[0] - goal[0], p.position[1] - goal[1])
        return d if d < 0.5 else None

    dist = wait_until(arrived, timeout=120, what="base1 at the goal", seen=lambda: base.xy_theta)
    print(f"Test B from the page: base1 stopped {dist:.3f} m from the goal clicked on the map")
    shot(bob, "bob-test-b")
    bob.get_by_role("button", name="Release").click(no_wait_after=True)
    wait_message(bob, r"release base1: ok")
    bob.context.close()
    assert dist <= 0.1, f"base1 stopped {dist:.3f} m from the goal"


@pytest.mark.timeout(900)  # its own waits are bounded: at load 10-17 its set-up was tried twice, past 300 s
def test_a_page_that_closes_stops_her_base_which_passes_to_the_queue_after_the_grace(browser, klass):
    base = klass.carol.robot("base1")
    # from its spawn (the origin, facing +x: 5 m of floor behind it), whatever the tests before did: Test B leaves
    # it at its goal with the plan's heading, and backing up from there it once met something ("collision base1:
    # bumper"), stood still, and bob's Queue took it over instead of queueing
    base.request(timeout=10)
    base.reset(timeout=10)
    wait_until(
        lambda: (p := base.xy_theta) is not None and np.allclose(p, (0.0, 0.0, 0.0), atol=0.01),
        timeout=10,
        what="base1 back at its spawn",
        seen=lambda: base.xy_theta,
    )
    base.release()
    mark = klass.carol.event_mark()
    alice = open_page(browser, klass)
    logged_in(alice, klass, "alice")
    select_robot(alice, klass, "alice", "base1")
    bob = open_page(browser, klass)
    logged_in(bob, klass, "bob")
    select_robot(bob, klass, "bob", "base1")
    for attempt in (1, 2, 3):
        queued, asked_twice = _alice_drives_and_bob_queues(alice, bob, base)
        if queued:
            break
        # at load her page's connection dropped (its pings unanswered 20 s), which lets go of her keys at once, as a
        # dropped page must: her base stood still, and bob's Queue took it over, as the rules allow. The test's
        # premise (bob queued behind a moving base) did not hold: bob gives it back and it is set up again
        print(f"attempt {attempt}: bob's Queue took base1 over (it stood still): set up again")
        press(bob, bob.get_by_role("button", name="Release"), r"release base1: ok", 60)
        alice.keyboard.up("ArrowLeft")
    else:
        pytest.fail("three times bob's Queue found base1 still: alice's page could not keep it moving")
    closed = time.monotonic()
    alice.context.close()  # with ← still held: its release never comes

    def still() -> bool:
        p = base.pose
        return p is not None and math.hypot(p.linear[0], p.linear[1]) < 0.02 and abs(p.angular[2]) < 0.02

    wait_until(still, timeout=15, what="base1 stopped after alice's page closed", seen=lambda: base.pose)
    stopped = time.monotonic() - closed
    wait_until(
        lambda: base.record.owner == "bob",
        timeout=120,  # the reconnect window and the grace are 60 s
        what="base1 passed to bob after the grace",
        seen=lambda: base.record,
    )
    passed = time.monotonic() - closed
    print(
        f"alice's page closed: base1 still after {stopped:.2f} s, bob's after {passed:.1f} s "
        f"(reconnect window {RECONNECT_S:.0f} s + grace {GRACE_S:.0f} s)"
    )
    if passed < RECONNECT_S + GRACE_S - 0.5:
        # passed early only where her lease lapsed, and the authority said so: the console renews the leases of its
        # pages' owners, and in CI (load 7-14) it stalled bob's page 30 s, then her base was bob's within 15 s of her
        # page's closing; another CI run (load 6-12) gave it to bob 32.0 s after (issue 45: leases renewed inside a
        # starved console)
        story = klass.carol.event_log.authority_events(mark, klass.carol.event_mark(), OWN_KINDS)
        lapsed = [e for e in story if e.object == "base1" and e.kind == "own_expired" and e.user == "alice"]
        # or bob's Queue, clicked a second time at load, reached the authority once her page had closed and her base
        # stood still, and took it over, as a request on a still robot does (run 37 of 2026-12-02: "handed over to
        # bob while still" 0.6 s after her page closed): lawful, and the grace then has nothing to judge
        took = [
            e
            for e in story
            if asked_twice
            and e.object == "base1"
            and e.kind == "own_revoked"
            and e.user == "alice"
            and "while still" in e.reason
        ]
        assert lapsed or took, (
            f"base1 was bob's {passed:.1f} s after alice's page closed, and her lease had not lapsed\n"
            f"base1's ownership events: {_ownership_story(klass, mark)}\n"
            f"console: {klass.procs.output(klass.console)[-3000:]}"
        )
        if lapsed:
            print(f"alice's lease lapsed before her page's reconnect window and grace ended: {lapsed[0].reason}")
        else:
            print(f"bob's second Queue took base1 over while it stood still: {took[-1].reason}")
    bob.get_by_text(re.compile(r"^mobile · owner: you")).wait_for()
    shot(bob, "bob-after-alice-left")
    bob.get_by_role("button", name="Release").click(no_wait_after=True)
    wait_message(bob, r"release base1: ok")
    bob.context.close()


def _alice_drives_and_bob_queues(alice, bob, base) -> tuple[bool, bool]:
    """alice owns base1 and turns it on the spot with ← held; bob clicks Queue while it moves. (True once bob waits
    at place 1, False where his Queue took it over: it stood still when his click reached the authority; whether he
    clicked Queue twice, the first unanswered in 30 s: that one may still reach the authority later.)"""
    press(
        alice, alice.get_by_role("button", name="Request"), r"request base1: (you own it|granted .*already owner)", 60
    )
    alice.locator("body").click(no_wait_after=True, position={"x": 5, "y": 5})
    # turning on the spot, for as long as it is held: backing towards the west wall, the base once reached something
    # (or stood still) before bob's Queue came at load, and his Queue took it over, as a request on a still robot does
    for n in (1, 2, 3):  # a key whose press met a dropped socket never reached the console: pressed again
        alice.keyboard.down("ArrowLeft")
        try:
            wait_until(lambda: base.record.state == "moving", timeout=10, what="base1 moving", seen=lambda: base.record)
            break
        except AssertionError:
            if n == 3:
                raise
            print(f"base1 still 10 s after alice's ← (run 15 of 2026-12-02): she presses it again ({n})")
            alice.keyboard.up("ArrowLeft")
    # moving: bob takes a place in the queue. Not waiting on navigations: in CI (load 10-16) this click once waited
    # 30 s on one (NiceGUI reloads a page whose connection timed out), a reload that resumes his session anyway
    from playwright.sync_api import TimeoutError as PlaywrightTimeoutError

    twice = False
    for attempt in (1, 2):  # a click a reload swallowed is clicked again (a second Queue keeps his place)
        twice = attempt == 2
        try:
            bob.get_by_role("button", name="Queue").click(no_wait_after=True, timeout=60_000)
            said = wait_message(bob, r"queue for base1: (queued at position 1|granted)", timeout=30)
            break
        except (AssertionError, PlaywrightTimeoutError) as e:
            if attempt == 2:
                raise
            print(f"bob's Queue said nothing in 30 s or was not clickable in 60 s, clicked again: {e}")
            back_in(bob)  # his session ended as his page reloaded (beside whole run 17, 2026-12-02)
    if "granted" in said:
        return False, twice
    bob.get_by_text(re.compile(r"^mobile · owner: alice .*your place: 1")).wait_for()
    return True, twice


OWN_KINDS = frozenset(str(k) for k in EventKind if k.startswith("own_"))


def _ownership_story(klass: Klass, since: int) -> list[str]:
    """base1's ownership events since mark ``since``, as carol (an instructor) heard them."""
    return [
        f"{e.kind} {e.user}: {e.reason}"
        for e in klass.carol.event_log.authority_events(since, klass.carol.event_mark(), OWN_KINDS)
        if e.object == "base1"
    ]


def test_a_wrong_password_shows_the_error_and_opens_no_session(browser, klass):
    page = open_page(browser, klass)
    log_in(page, "dave", "not-" + klass.passwords["dave"])
    alert = page.get_by_role("alert")
    wait_until(
        lambda: "wrong password" in alert.inner_text(), timeout=30, what="the login error", seen=alert.inner_text
    )
    shot(page, "wrong-password")
    assert ("user", "dave") not in klass.carol.fabric.live_peers("user")
    assert page.get_by_role("button", name="Request").count() == 0
    page.context.close()


def test_the_pages_ask_no_host_but_the_console_server(browser, klass):
    page = open_page(browser, klass)
    logged_in(page, klass, "dave")
    page.get_by_label(re.compile("^Live view")).wait_for()
    page.wait_for_timeout(2000)
    shot(page, "dave-view")
    page.context.close()
    assert any(urlsplit(u).path.startswith("/_nicegui") for u in REQUESTS), REQUESTS  # its assets came from the console
    elsewhere = sorted(
        {u for u in REQUESTS if urlsplit(u).netloc != klass.host and not u.startswith(("data:", "blob:"))}
    )
    assert not elsewhere, f"the pages asked other hosts: {elsewhere}"


def test_the_3d_view_draws_the_arm_and_a_drag_in_it_moves_the_ik_target_that_apply_ik_reaches(browser, klass):
    """The 3D view draws arm1's links at its live joints (a link ends at the flange the sim reports); the height
    field and a real mouse drag of the orange sphere move the scene's IK target (read through the Python API), the
    drag on the target's own plane; Apply IK then puts the flange on it."""
    arm, seen = klass.carol.robot("arm1"), klass.carol.object("target")
    wait_until(lambda: arm.flange is not None, timeout=30, what="arm1's flange")
    sx, sy, sz, yaw = next(r.pose for r in klass.carol.info().robots if r.id == "arm1")
    # a target well inside arm1's reach (0.2 m ahead of its base, 0.2 m up), whatever the tests before left
    klass.carol.object("target").set_pose([sx + 0.2 * math.cos(yaw), sy + 0.2 * math.sin(yaw), sz + 0.2])
    dave = open_page(browser, klass)
    logged_in(dave, klass, "dave")
    dave.get_by_role("button", name="arm1", exact=True).click(no_wait_after=True)
    dave.get_by_role("button", name="Request").click(no_wait_after=True)
    wait_message(dave, r"request arm1: you own it")

    def drawn() -> dict | None:
        out = dave.evaluate(SCENE3D_JS)
        return out if out and out.get("target") and len(out["ends"]) >= 12 else None

    scene = wait_until(
        drawn, timeout=30, what="the 3D view with arm1's links and the target", seen=lambda: dave.evaluate(SCENE3D_JS)
    )
    flange = np.asarray(arm.flange.position)
    assert min(math.dist(e, flange) for e in scene["ends"]) <= 0.005, (
        scene["ends"],
        flange,
    )  # drawn at its live joints

    z = round(float(seen.pose.position[2]) - 0.02, 3)
    height = dave.get_by_label("IK target height z in metres")
    height.fill(f"{z}")
    height.press("Enter")
    wait_until(
        lambda: abs(seen.pose.position[2] - z) <= 1e-6,
        timeout=10,
        what=f"the target's height at {z}",
        seen=lambda: seen.pose,
    )
    before = np.asarray(seen.pose.position, dtype=float)
    wait_until(
        lambda: (s := drawn()) and abs(s["target"][2] - z) <= 1e-4, timeout=10, what="the sphere at the new height"
    )
    drag_sphere(dave, drawn()["screen"])
    wait_until(
        lambda: np.linalg.norm(np.asarray(seen.pose.position)[:2] - before[:2]) >= 0.005,
        timeout=10,
        what="the target dragged (read through the Python API)",
        seen=lambda: (before, seen.pose.position),
    )
    target = np.asarray(seen.pose.position, dtype=float)
    assert target[2] == pytest.approx(z, abs=1e-6)  # dragged on its own plane
    assert np.linalg.norm(target - before) <= 0.1
    wait_message(dave, r"IK target dragged to")
    ik = dave.get_by_text(re.compile(r"^IK: "))
    wait_until(lambda: ik.inner_text().startswith("IK: ["), timeout=30, what="the IK solution", seen=ik.inner_text)
    shot(dave, "3d-view-dragged")
    dave.get_by_role("button", name="Apply IK").click(no_wait_after=True)
    wait_message(dave, r"apply IK .*: ok")

    def on_target() -> tuple[float, int] | None:
        p = arm.flange
        if p is None:
            return None
        err = float(np.linalg.norm(np.asarray(p.position) - target))
        return (err, p.header.seq) if err <= 1e-3 else None

    # there, and still there 20 flange poses later: at rest on it, not passing through (a wrist joint that only
    # turns the flange may still be settling on a loaded box: CI saw the flange on the target with |dq| > 1e-3)
    first = wait_until(
        on_target, timeout=30, what="arm1's flange at the dragged target", seen=lambda: (arm.flange, target)
    )
    wait_until(
        lambda: (o := on_target()) is not None and o[1] >= first[1] + 20,
        timeout=30,
        what="arm1's flange to stay at the dragged target",
        seen=lambda: (arm.flange, target),
    )
    wait_until(
        lambda: min(math.dist(e, target) for e in drawn()["ends"]) <= 0.005,
        timeout=10,
        what="the 3D arm drawn at the target",
    )
    shot(dave, "3d-view-reached")
    dave.get_by_role("button", name="Release").click(no_wait_after=True)
    wait_message(dave, r"release arm1: ok")
    dave.context.close()


def _in_viewport(box: dict | None, vp: dict) -> bool:
    return (
        box is not None
        and box["x"] >= 0
        and box["y"] >= 0
        and box["x"] + box["width"] <= vp["width"] + 0.5
        and box["y"] + box["height"] <= vp["height"] + 0.5
    )


def test_the_selected_robots_panel_sits_beside_its_view_and_fits_1024x700_and_stacks_at_800x600(browser, klass):
    """Only the selected robot's panel shows (bob selected base1: no arm panel); at 1024x700 the map and Plan are
    both on the screen without scrolling, side by side; at 800x600 the base panel and the map stack."""
    page = new_context(browser, viewport={"width": 1024, "height": 700}).new_page()
    # 60 s for an action: at the suite's load (15-35 on two cores) a page's renderer, drawing its 3D view in software
    # GL, once took over 30 s to hit-test a visible, enabled, stable button (CI run of 2026-11-30, bob's Request)
    page.set_default_timeout(60_000)
    page.goto(klass.url, timeout=60_000)
    logged_in(page, klass, "bob")
    page.get_by_role("button", name="base1", exact=True).click(no_wait_after=True)
    plan, live = page.get_by_role("button", name="Plan"), page.get_by_label(re.compile("^Live view"))
    wait_until(
        lambda: plan.is_visible() and not page.get_by_role("slider", name=re.compile("^J1")).is_visible(),
        timeout=10,
        what="base1's panel shown and no arm panel",
    )
    vp = page.viewport_size
    wait_until(
        lambda: _in_viewport(plan.bounding_box(), vp) and _in_viewport(live.bounding_box(), vp),
        timeout=10,
        what="Plan and the map both in the 1024x700 viewport",
        seen=lambda: (plan.bounding_box(), live.bounding_box()),
    )
    assert plan.bounding_box()["x"] + plan.bounding_box()["width"] <= live.bounding_box()["x"]  # beside it
    shot(page, "layout-1024x700")
    page.set_viewport_size({"width": 800, "height": 600})
    wait_until(
        lambda: live.bounding_box()["y"] >= plan.bounding_box()["y"] + plan.bounding_box()["height"],
        timeout=10,
        what="the map stacked under the base panel at 800x600",
        seen=lambda: (plan.bounding_box(), live.bounding_box()),
    )
    shot(page, "layout-800x600")
    page.context.close()


def test_the_page_has_a_language_headings_named_sliders_with_numbers_and_grey_disabled_controls(browser, klass):
    page = open_page(browser, klass)
    logged_in(page, klass, "bob")
    page.get_by_role("button", name="arm1", exact=True).click(no_wait_after=True)
    page.get_by_role("slider", name=re.compile("^J1")).wait_for()
    assert page.evaluate("() => document.documentElement.lang") == "en-US"
    for name in ("Robots", "Events", "3D view", re.compile("^arm arm1")):
        assert page.get_by_role("heading", name=name).count() == 1, name
    assert page.get_by_role("heading", level=1).count() == 1
    sliders = page.get_by_role("slider")
    assert sliders.count() == 7  # six joints and the speed, each named, each showing its number
    for i in range(sliders.count()):
        assert sliders.nth(i).get_attribute("aria-label"), i
    assert page.locator(".q-slider__pin-value-marker-text, .q-slider__text").count() >= 7
    assert page.get_by_label("Nudge step").count() >= 1
    stop = page.get_by_role("button", name="Stop", exact=True).first
    wait_until(lambda: stop.is_disabled(), timeout=10, what="bob's Stop disabled (he owns nothing)")
    assert "grayscale" in stop.evaluate("(e) => getComputedStyle(e).filter")
    page.context.close()


def _scale_px_per_m(page) -> float:
    """The scale bar's screen pixels per metre (0 while the overlay is between two draws)."""
    bar = page.locator(".rf-scale-bar").first
    box = page.locator(".rf-scale-bar-line").first.bounding_box()
    return box["width"] / float(bar.get_attribute("data-metres")) if box else 0.0


def test_a_goal_typed_in_metres_is_placed_a_bad_one_is_refused_in_plain_words_and_the_map_zooms_with_its_scale_bar(
    browser, klass
):
    """The goal's x and y fields: a word is refused with what to type (the goal stays), numbers place the goal (the
    scene's goal pointer, read through the Python API, and the ring on the map). The legend names the map's marks;
    the scale bar's length on the screen matches the map's own scale, and twice it after Zoom in; a click on the
    zoomed map lands where it is drawn."""
    from user_peer.console.state import scene_layout

    info = klass.carol.info()
    goal_obj = klass.carol.object(next(o.id for o in info.objects if o.kind == "goal_pointer"))
    base = klass.carol.robot("base1")
    wait_until(lambda: base.xy_theta is not None, timeout=30, what="base1's pose")
    bx, by, _ = base.xy_theta
    d = math.hypot(bx, by)
    ux, uy = (-bx / d, -by / d) if d > 0.1 else (1.0, 0.0)
    want = (round(bx + 0.6 * ux, 2), round(by + 0.6 * uy, 2))  # 0.6 m from base1 towards the middle
    dave = open_page(browser, klass)
    logged_in(dave, klass, "dave")
    dave.get_by_role("button", name="base1", exact=True).click(no_wait_after=True)
    # base1 selected, its panel shown: the zoom below centres on it only once it is (at load a selection's handle
    # came after the zoom's click once, and the zoom said "the map whole")
    plan = dave.get_by_role("button", name="Plan")
    wait_until(
        lambda: plan.is_visible(), timeout=30, what="base1's panel", seen=lambda: (message(dave), _socket_state(dave))
    )
    gx, gy = dave.get_by_label("Goal x in metres"), dave.get_by_label("Goal y in metres")
    gx.fill("two")
    gy.fill(f"{want[1]}")
    before = goal_obj.pose
    dave.get_by_role("button", name="Set goal").click(no_wait_after=True)
    text = wait_message(dave, r"^Set goal: Goal x 'two' is not a number: type metres with a point")
    assert "Goal y" not in text, text
    assert goal_obj.pose == before  # nothing moved
    gx.fill(f"{want[0]}".replace(".", ","))  # a decimal comma reads as the point
    gx.press("Enter")
    wait_message(dave, re.escape(f"goal at ({want[0]:.2f}, {want[1]:.2f})"))
    wait_until(
        lambda: goal_obj.pose is not None and np.allclose(goal_obj.pose.position[:2], want, atol=1e-6),
        timeout=10,
        what=f"the goal pointer at {want} (read through the Python API)",
        seen=lambda: goal_obj.pose,
    )
    ring = dave.locator('svg circle[r="6"][stroke="#2f9e44"]')
    ring.wait_for(state="attached")
    legend = dave.get_by_label("Map legend")
    assert legend.is_visible() and "LIDAR hits" in legend.inner_text() and "your robot" in legend.inner_text()

    whole, _ = scene_layout(info)
    live = dave.get_by_label(re.compile("^Live view"))
    live.scroll_into_view_if_needed()
    screen = live.bounding_box()["width"] / (whole.xmax - whole.xmin)  # the map's screen pixels per metre
    wait_until(
        lambda: abs(_scale_px_per_m(dave) / screen - 1) <= 0.02,
        timeout=10,
        what="the scale bar at the map's scale",
        seen=lambda: (_scale_px_per_m(dave), screen),
    )
    shot(dave, "goal-typed")
    # a zoom centres on base1 once the page follows it, as its panel's pose shows (at load it came after the panel,
    # and the zoom said "around its middle": make test, 2026-12-01)
    state = dave.locator(".rf-base-state")
    wait_until(
        lambda: state.inner_text().startswith("pose ("),
        timeout=30,
        what="base1's pose on its panel",
        seen=state.inner_text,
    )
    dave.get_by_role("button", name="Zoom in").click(no_wait_after=True)
    wait_message(dave, r"^zoom x2: the map around base1, ")  # said in the status line, for a screen reader too
    wait_until(
        lambda: abs(_scale_px_per_m(dave) / (2 * screen) - 1) <= 0.02,
        timeout=10,
        what="the scale bar twice as long a metre",
        seen=lambda: (_scale_px_per_m(dave), 2 * screen),
    )
    # the goal ring redrawn on the zoomed map; a click on its middle places the goal there again
    wait_until(
        lambda: (b := ring.bounding_box()) is not None and b["width"] > 0,
        timeout=10,
        what="the goal ring on the zoomed map",
    )
    box = live.locator("img").first.bounding_box()
    cx, cy = _center(dave, 'svg circle[r="6"][stroke="#2f9e44"]')
    live.locator("img").first.click(no_wait_after=True, position={"x": cx - box["x"], "y": cy - box["y"]})
    wait_message(dave, r"^goal at ")
    assert _clicked_near(message(dave), want), message(dave)
    shot(dave, "map-zoomed")
    dave.context.close()


def _clicked_near(text: str, want: tuple[float, float]) -> bool:
    """The page's message names a goal within 3 cm of ``want`` (a screen pixel at zoom x2 is about 1.3 cm here)."""
    m = re.search(r"goal at \((-?[0-9.]+), (-?[0-9.]+)\)", text)
    return m is not None and math.dist((float(m.group(1)), float(m.group(2))), want) <= 0.03


def _events(page) -> str:
    return page.locator(".nicegui-log").first.inner_text()


def test_a_reload_keeps_her_session_her_robot_and_her_event_log_until_she_logs_out(browser, klass):
    """alice logs in with her login card's typable password (``secure init``) and owns base1 and reloads her tab: the page comes back as she left it, without her password (base1
    selected and hers, read through the Python API, her event log's lines there); Log out ends her session at
    once (base1 released) and a reload after it stays at the login."""
    base = klass.carol.robot("base1")
    alice = open_page(browser, klass)
    card = klass.cards["alice"].read_text()  # she logs in with what her login card says
    log_in(alice, "alice", re.search(r"  Password  (\S+)\n", card).group(1))
    alice.get_by_text(f"world {klass.world} · alice").wait_for(timeout=60_000)
    alice.get_by_role("button", name="base1", exact=True).click(no_wait_after=True)
    alice.get_by_role("button", name="Request").click(no_wait_after=True)
    wait_message(alice, r"request base1: you own it")
    line = "ownership base1: nobody -> alice"
    wait_until(
        lambda: line in _events(alice),
        timeout=10,
        what="the ownership line in her event log",
        seen=lambda: _events(alice),
    )
    assert alice.evaluate("() => sessionStorage.getItem('rf-console-session')")  # the tab's ticket
    alice.reload(timeout=60_000)
    alice.get_by_text(f"world {klass.world} · alice").wait_for(timeout=60_000)  # nothing typed
    alice.get_by_text(re.compile(r"^base base1 .* owner: you")).wait_for()  # base1 selected again, still hers
    assert base.record.owner == "alice"
    wait_until(
        lambda: line in _events(alice),
        timeout=10,
        what="her event log back after the reload",
        seen=lambda: _events(alice),
    )
    shot(alice, "reloaded")
    alice.get_by_role("button", name="Log out").click()
    alice.get_by_role("button", name="Log in").wait_for(timeout=60_000)
    wait_until(
        lambda: base.record.owner != "alice", timeout=30, what="base1 released at the logout", seen=lambda: base.record
    )
    assert alice.evaluate("() => sessionStorage.getItem('rf-console-session')") is None
    alice.reload(timeout=60_000)
    alice.get_by_role("button", name="Log in").wait_for(timeout=60_000)
    alice.get_by_label("Name").fill("alice")  # a page that came back would have left the login card by now
    assert alice.get_by_text(f"world {klass.world} · alice").count() == 0
    alice.context.close()


A11Y = Path(__file__).resolve().parents[2] / "a11y"  # tests/a11y: package.json and its lock pin axe-core


def axe_js() -> Path:
    """axe-core's ``axe.min.js``: $RF_AXE_JS, else tests/a11y's (``make test`` runs ``npm ci`` there; a test run
    without it runs ``npm ci`` itself, from the npm registry or npm's cache), else npm's global one."""
    import os
    import subprocess

    def found() -> Path | None:
        for p in (os.environ.get("RF_AXE_JS"), A11Y / "node_modules/axe-core/axe.min.js"):
            if p and Path(p).is_file():
                return Path(p)
        if shutil.which("npm"):
            root = subprocess.run(["npm", "root", "-g"], capture_output=True, text=True, timeout=60).stdout.strip()
            if root and (Path(root) / "axe-core/axe.min.js").is_file():
                return Path(root) / "axe-core/axe.min.js"
        return None

    path = found()
    if path is None and shutil.which("npm"):
        out = subprocess.run(
            ["npm", "ci", "--prefix", str(A11Y), "--no-audit", "--no-fund", "--loglevel=error"],
            capture_output=True,
            text=True,
            timeout=300,
        )
        path = found()
        assert path is not None, f"npm ci in {A11Y} did not install axe-core: {out.stderr[-2000:]}"
    assert path is not None, (
        "axe-core is not installed and there is no npm to install it (apt-get install npm; make test)"
    )
    return path


AXE_RUN = """async () => {
  const r = await axe.run(document, {resultTypes: ['violations']});
  return r.violations.map((v) => ({id: v.id, impact: v.impact, help: v.help,
                                   nodes: v.nodes.slice(0, 5).map((n) => n.target.join(' ') + ' ' + (n.html || '').slice(0, 300) + ': ' + n.failureSummary)}));
}"""


def axe_violations(page) -> list[dict]:
    """axe-core's serious and critical violations of the page as it is now (every rule axe runs by default)."""
    page.add_script_tag(content=axe_js().read_text(encoding="utf-8"))  # inline: the page asks no other host
    return [v for v in page.evaluate(AXE_RUN) if v["impact"] in ("serious", "critical")]


def test_axe_core_finds_no_serious_or_critical_violation_on_the_login_card_and_the_students_page(browser, klass):
    """axe-core (npm) in Chromium: the login card, then bob's page with the arm selected (its panel and the 3D
    view, the base's map) and with base1 selected (the base panel, the goal fields, the map's zoom and legend)."""
    page = open_page(browser, klass)
    page.get_by_role("button", name="Log in").wait_for()
    found = {"login": axe_violations(page)}
    logged_in(page, klass, "bob")
    page.get_by_role("button", name="arm1", exact=True).click(no_wait_after=True)
    page.get_by_role("slider", name=re.compile("^J1")).wait_for()
    page.locator(".rf-scale-bar").first.wait_for(state="attached")
    found["arm selected"] = axe_violations(page)
    page.get_by_role("button", name="base1", exact=True).click(no_wait_after=True)
    page.get_by_role("button", name="Set goal").wait_for()
    found["base selected"] = axe_violations(page)
    shot(page, "axe")
    page.context.close()
    assert not any(found.values()), json.dumps(found, indent=1)


def open_teacher(browser, klass: Klass, name: str):
    """The teacher's page, logged in as ``name`` (the login card's name and password)."""
    page = new_context(browser, viewport=VIEWPORT).new_page()
    page.on("request", lambda r: REQUESTS.append(r.url))
    page.set_default_timeout(30_000)
    page.goto(klass.url + "teacher", timeout=60_000)
    log_in(page, name, klass.passwords[name])
    return page


def test_the_teacher_releases_a_robot_a_student_holds_a_reload_keeps_her_in_and_a_student_cannot_open_the_teachers_page(
    browser, klass
):
    """alice's login card asks for her login card's name and password (the console found that the router asks for
    logins); she owns arm1 from her page; carol (an instructor) sees it on the teacher's page and releases it: the
    authority takes it back (read through the Python API), alice's page shows it free, and the class's event log
    says who did it. bob, a student, is refused the teacher's page before any session of his opens. axe-core finds
    no serious or critical violation on the teacher's page."""
    arm = klass.carol.robot("arm1")
    alice = open_page(browser, klass)
    alice.get_by_text(login_caption(True), exact=True).wait_for()  # a class's world: the card asks for her login card's
    logged_in(alice, klass, "alice")
    alice.get_by_role("button", name="arm1", exact=True).click(no_wait_after=True)
    alice.get_by_role("button", name="Request").click(no_wait_after=True)
    wait_message(alice, r"request arm1: you own it")

    bob = open_teacher(browser, klass, "bob")
    bob.get_by_text("Refused: the teacher's page is for instructors: bob is not one of this console's").wait_for(
        timeout=60_000
    )
    assert bob.get_by_role("button", name="Stop all").count() == 0

    carol = open_teacher(browser, klass, "carol")
    carol.get_by_text(f"teacher's page · world {klass.world} · carol").wait_for(timeout=60_000)
    release = carol.get_by_role("button", name="Release arm1")
    release.wait_for(timeout=30_000)  # shown once the class's table says someone owns arm1
    carol.get_by_role("cell", name="alice", exact=True).first.wait_for()  # the class table: alice, her page
    shot(carol, "teacher")
    release.click(no_wait_after=True)
    wait_until(
        lambda: "arm1 taken back from alice by instructor carol" in message(carol),
        timeout=30,
        what="the teacher's page to say what it did",
        seen=lambda: message(carol),
    )
    wait_until(
        lambda: arm.record is not None and arm.record.owner == "",
        timeout=30,
        what="arm1 free (read through the Python API)",
        seen=lambda: arm.record,
    )
    alice.get_by_text(re.compile(r"^arm arm1 .* owner: nobody")).wait_for(timeout=30_000)
    wait_message(alice, r"arm1 is no longer yours: it is free now")
    wait_until(
        lambda: (
            "ownership arm1: alice -> nobody" in _events(alice)
            and "taken back from alice by instructor carol" in _events(alice)
        ),
        timeout=30,
        what="alice's event log to say it was taken back, and by whom",
        seen=lambda: _events(alice),
    )
    shot(alice, "alice-released-by-teacher")
    found = axe_violations(carol)
    shot(carol, "teacher-after")
    assert not found, json.dumps(found, indent=1)
    # a reload keeps her session, with no password typed; Log out ends it and the tab is back at its login card
    assert carol.evaluate("() => sessionStorage.getItem('rf-teacher-session')")
    carol.reload(timeout=60_000)
    carol.get_by_text(f"teacher's page · world {klass.world} · carol").wait_for(timeout=60_000)
    carol.get_by_role("button", name="Lock arm1", exact=True).wait_for(timeout=30_000)  # the robots table is back
    carol.get_by_role("button", name="Log out").click()
    carol.get_by_role("button", name="Log in").wait_for(timeout=60_000)
    assert carol.evaluate("() => sessionStorage.getItem('rf-teacher-session')") is None
    carol.reload(timeout=60_000)
    carol.get_by_role("button", name="Log in").wait_for(timeout=60_000)  # no ticket: the login card


def test_a_console_without_its_3d_view_serves_the_map_and_the_panels_alone(browser, klass):
    """``console --no-3d``: the 2D page (the map beside the base's panel, the arm's panel alone), for a small server
    or to run the class's bench beside the 3D page."""
    import signal

    args = list(klass.console.args)
    ep = args[args.index("--connect") + 1]
    web = free_port()
    flat = klass.procs.start(
        robofabric_cmd("console", "--world", klass.world, "--connect", ep, "--listen", f"127.0.0.1:{web}", "--no-3d"),
        name="console-2d",
    )
    try:
        url = f"http://127.0.0.1:{web}/"
        wait_until(
            lambda: f"console: open {url}" in klass.procs.output(flat),
            timeout=60,
            what="the 2D console's URL",
            seen=lambda: klass.procs.output(flat)[-2000:],
        )
        page = new_context(browser, viewport=VIEWPORT).new_page()
        page.set_default_timeout(30_000)
        page.goto(url, timeout=60_000)
        logged_in(page, klass, "dave")
        page.locator(".rf-map").wait_for()
        page.get_by_role("button", name="Apply IK").wait_for()  # the arm's panel, without the 3D view beside it
        assert page.locator(".rf-scene3d").count() == 0
        shot(page, "dave-2d")
    finally:
        klass.procs.kill(flat, signal.SIGTERM)
