"""``robofabric bench console``: N browser pages on one ``robofabric console``, each a student driving her own base.

Per page count N, a fresh open world: a router, a sim (``--scene warehouse --no-scene-robots`` with N Reeman
bases) and one console server. N pages in Debian's headless ``chromium`` (through ``playwright``, one
context each) log in as ``s0``..``sN-1``, select and request ``baseI`` and hold ← (speed 2): every base turns
in place, each page refreshing its twist. Then, page after page, for ``--seconds``:

- **key to motion**: the page lets go of ←, and once its base is still presses it again; the time from the
  press (this process's clock) to the first pose of that base turning (the sim's stamp, same host) is one
  sample;
- **view lag, measured in the page**: ``Date.now()`` against the sim's wall stamp of the pose the page shows
  (the base panel carries it as ``data-pose-wall-ms``), read in one ``page.evaluate``;
- **the console server's CPU** over the whole drive (cores, from /proc);
- **the browsers' CPU per page** over the whole drive: every Chromium process this benchmark started (its
  renderers, its GPU process, the browser itself; from /proc), summed and divided by the pages, and the
  renderers' share alone: what one student's page costs the machine that draws it; and a page's join (load,
  log in, request), as the CPU seconds of the processes it started (its renderer), median over the pages;
- **robots lost** (a base whose record no longer names its student) and **refusals** (a page whose message
  line says a command was refused or failed): both should be 0.

The pages join one after another (each join timed and its CPU counted alone); ``--together`` asks for every page
at once, as a class does when the teacher says go, and shares the joins' CPU out. ``--robots R`` puts the pages in
a world of R bases: a few pages in a class-sized world give the server's cost per page without a class of browsers.

Pages, sim and console share this machine (and the chromium processes are the largest load): the figures are
the whole class on one box, not the server alone.

Chromium composites the pages as it chooses on this machine (no GPU: in software) unless ``--swiftshader``, which
gives it the flags of the tests' browsers (``viewer_web.CHROMIUM_ARGS``): WebGL drawn by SwiftShader's software GL,
the page composited on the CPU. Until 2026-12-03 those flags composited through SwiftShader too: every repaint then
cost the GPU process ~20 ms of CPU for a 1280 x 1350 page, whatever changed (a page driving its base at
``--view-fps 2``: 0.59 of a core, 0.21 composited on the CPU; docs/testing.md).
"""

from __future__ import annotations

import os
import sys
import time
import uuid
from pathlib import Path
from typing import Annotated, Any, Optional

import typer

from robofabric.bench.common import append, box_idle_s, machine, pct, proc_cpu_s, proc_waited_s
from robots.kinds import facts

__all__ = ["command", "run_one"]

LAG_JS = (
    "() => { const e = document.querySelector('.rf-base-state'); "
    "return [Date.now(), e ? Number(e.dataset.poseWallMs || 0) : 0]; }"
)
REFUSED = ("NotOwner", "Rejected", "Timeout", "Unreachable", "Error")


def _until(predicate: Any, timeout: float) -> Any:
    """``predicate()``'s first truthy value within ``timeout`` s (polled every 5 ms), else None."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value or time.monotonic() > deadline:
            return value or None
        time.sleep(0.005)


def _children() -> dict[int, list[int]]:
    """Every process's children, from /proc (ppid is the field after the name)."""
    kids: dict[int, list[int]] = {}
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                with open(f"/proc/{d}/stat") as f:
                    ppid = int(f.read().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            kids.setdefault(ppid, []).append(int(d))
    return kids


def chromium_cpu_s(root: int) -> dict[str, float]:
    """CPU seconds so far of the Chromium processes under ``root`` (this process: playwright's driver starts the
    browser), by Chromium's ``--type`` (``renderer``, ``gpu-process``, ``utility``, ``zygote``; ``browser`` for the
    browser process itself). A process that ended before the second reading drops out of the difference."""
    kids, out, todo = _children(), {}, [root]
    while todo:
        pid = todo.pop()
        todo.extend(kids.get(pid, []))
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                argv = f.read().replace(b"\0", b" ").split()  # a forked renderer's title is one string
        except OSError:
            continue
        if not argv or b"chrom" not in argv[0]:
            continue
        kind = next((a.split(b"=", 1)[1].decode() for a in argv if a.startswith(b"--type=")), "browser")
        out[f"{kind}:{pid}"] = proc_cpu_s(pid)
    return out


def _joined_renderer(before: dict[str, float], after: dict[str, float], claimed: set[str]) -> float:
    """The CPU seconds a page's join cost its renderer: of the renderers no earlier page holds, the one that
    worked most meanwhile (Chromium keeps a spare renderer ready, so a page's renderer may predate its join;
    the processes new since ``before`` alone read 0.0 s when the spare took the page). Claimed for that page."""
    grew = {
        k: v - before.get(k, 0.0) for k, v in after.items() if k.startswith("renderer:") and k not in claimed and v == v
    }
    if not grew:
        return float("nan")
    key = max(grew, key=lambda k: grew[k])
    claimed.add(key)
    return grew[key]


def _per_page(before: dict[str, float], after: dict[str, float], seconds: float, pages: int) -> tuple[float, float]:
    """(all Chromium processes, renderers only) in cores per page between two :func:`chromium_cpu_s` readings."""
    used = {k: v - before.get(k, 0.0) for k, v in after.items()}
    total = sum(v for v in used.values() if v == v)
    renderers = sum(v for k, v in used.items() if k.startswith("renderer:") and v == v)
    n = max(pages, 1) * seconds
    return total / n, renderers / n


def _by_kind(before: dict[str, float], after: dict[str, float], seconds: float) -> str:
    """Cores by Chromium process kind between two :func:`chromium_cpu_s` readings: where the pages' cost goes."""
    kinds = sorted({k.split(":")[0] for k in after})
    return ", ".join(
        f"{kind} {sum(v - before.get(k, 0.0) for k, v in after.items() if k.split(':')[0] == kind) / seconds:.2f}"
        for kind in kinds
    )


def _status(page: Any) -> str | None:
    """A page's message line; None when the page has none any more (it lost its connection for longer than the
    console's reconnect window and went back to the login). A page whose renderer is starved (load 30 beside the
    run) answers slowly, not never: 5 s once counted such a page as back at its login, so it is given 30 s."""
    status = page.get_by_role("status")
    try:
        return status.inner_text(timeout=30_000)
    except Exception:
        return None


def _reloads(seen: list[str], i: int, text: str) -> None:
    """A page's console line that says it reloads (NiceGUI logs why: a reconnect that timed out, a handshake the
    server refused because it forgot the page): kept and printed, since a reload is a page back at its login."""
    if "reloading" in text or "falling back" in text:
        seen.append(f"page {i}: {text}")
        print(f"  page {i}: {text}", file=sys.stderr, flush=True)


def _join(page: Any, url: str, i: int, *, loaded: bool = False) -> list[float]:
    """Student ``s{i}`` logs in, selects and requests ``base{i}`` and holds ← at speed 2; the times of her steps.
    ``loaded``: the page was asked for already (its login form is awaited, not requested again)."""
    if not loaded:
        page.goto(url, timeout=120_000)
    page.get_by_label("Name").fill(f"s{i}")
    steps = [time.monotonic()]
    page.get_by_role("button", name="Log in").click()
    page.get_by_role("button", name=f"base{i}", exact=True).click()
    steps.append(time.monotonic())
    page.get_by_role("button", name="Request").click()
    page.get_by_text(f"request base{i}: you own it").wait_for()
    steps.append(time.monotonic())
    page.locator("body").click(position={"x": 5, "y": 5})
    page.keyboard.press("2")
    page.keyboard.down("ArrowLeft")
    return steps


def _new_page(browser: Any, i: int, reloads: list[str]) -> Any:
    page = browser.new_context(viewport={"width": 1280, "height": 1350}).new_page()
    page.on("console", lambda m, i=i: _reloads(reloads, i, m.text))
    page.set_default_timeout(60_000)
    return page


def _open_pages(
    browser: Any, url: str, n: int, reloads: list[str], *, together: bool
) -> tuple[list, list[int], list[float], list[float]]:
    """N pages logged in and driving: (pages, their bases, their join times, their joins' CPU seconds). One after
    another (each page's join timed and its new processes' CPU counted alone), or ``together``: every page asked
    for at once, as a class does when the teacher says go, then each logs in (a join's time counts from the
    first request; its CPU is all the new processes' CPU shared out)."""
    pages: list[Any] = []
    bases: list[int] = []
    joined: list[float] = []
    join_cpu: list[float] = []
    claimed: set[str] = set()  # the renderers of the pages already in
    t_all, cpu_all = time.monotonic(), chromium_cpu_s(os.getpid())
    opened = []
    for i in range(n):
        page = _new_page(browser, i, reloads)
        if together:
            page.goto(url, wait_until="commit", timeout=120_000)  # the request is out; its loading goes on meanwhile
        opened.append((i, page))
    for i, page in opened:
        t, cpu_before = (t_all, cpu_all) if together else (time.monotonic(), chromium_cpu_s(os.getpid()))
        try:
            steps = _join(page, url, i, loaded=together)
        except Exception as exc:  # a page that did not get in: counted, and the class goes on without it
            print(
                f"  page {i}: did not join: {str(exc).splitlines()[0]} (its message line: {_status(page)!r})",
                file=sys.stderr,
                flush=True,
            )
            page.context.close()
            continue
        pages.append(page)
        bases.append(i)
        joined.append(time.monotonic() - t)
        if not together:
            join_cpu.append(_joined_renderer(cpu_before, chromium_cpu_s(os.getpid()), claimed))
        print(
            f"  page {i}: joined in {joined[-1]:.1f} s (page {steps[0] - t:.1f}, login {steps[1] - steps[0]:.1f}, request "
            f"{steps[2] - steps[1]:.1f}"
            + ("" if together else f"; its renderer's CPU {join_cpu[-1]:.1f} s")
            + f"), load {os.getloadavg()[0]:.1f}",
            file=sys.stderr,
            flush=True,
        )
    if together and pages:
        new = sum(v for k, v in chromium_cpu_s(os.getpid()).items() if k not in cpu_all and v == v)
        join_cpu = [new / len(pages)] * len(pages)
    return pages, bases, joined, join_cpu


def browser_args(swiftshader: bool) -> list[str]:
    """Chromium's flags: the viewer benchmark's, less its forced SwiftShader GL and CPU compositing unless
    ``swiftshader``."""
    from robofabric.bench.viewer_web import CHROMIUM_ARGS

    forced = ("swiftshader", "gpu-compositing")
    return list(CHROMIUM_ARGS) if swiftshader else [a for a in CHROMIUM_ARGS if not any(f in a for f in forced)]


def _start_class(
    procs: Any,
    url: str,
    first: int,
    clients: int,
    seconds: float,
    arms: int = 0,
    targets: str = "",
    one_address: bool = False,
) -> Any:
    """The emulated students (:mod:`robofabric.bench.console_client`, one process of their own so that their
    CPU is neither the server's nor the measuring pages'): ``c{first}``.. on ``base{first}``.., all in; each from
    her own loopback address, or all from 127.0.0.1 (``one_address``: a class behind one NAT)."""
    from robofabric.bench.console_client import JOIN_WAIT_S
    from robofabric.testing import wait_until

    proc = procs.start(
        [
            sys.executable,
            "-m",
            "robofabric.bench.console_client",
            url,
            "--first",
            str(first),
            "--count",
            str(clients),
            "--seconds",
            str(seconds),
            "--arms",
            str(arms),
            f"--targets={targets}",
        ]
        + (["--one-address"] if one_address else []),
        name="clients",
    )
    # each student gives up on her own (JOIN_WAIT_S a step, at most 10 steps with an arm): this is only a backstop
    wait_until(
        lambda: f"of {clients} joined" in procs.output(proc) or proc.poll() is not None,
        timeout=60 + 10 * JOIN_WAIT_S,
        what=f"{clients} emulated students in",
        seen=lambda: procs.output(proc)[-1500:],
    )
    if proc.poll() is not None:
        raise RuntimeError(f"the emulated students' process ended with {proc.returncode}: {procs.output(proc)[-800:]}")
    line = procs.output(proc).split("clients: ", 1)[-1].split("\n", 1)[0]
    print(f"  emulated students: {line}, load {os.getloadavg()[0]:.1f}", file=sys.stderr, flush=True)
    return proc


def _arm_targets(fab: Any, world: str, arms: int) -> str:
    """Each arm's first IK target for its student: 0.2 m ahead of its base and 0.3 m up (the arms are placed by
    the sim, so their spawn poses are read from ``srv/world``), as ``x,y,z;...`` in arm order."""
    import math

    from fabric import keys
    from fabric.interfaces import WorldInfo
    from robofabric.testing import wait_until

    if not arms:
        return ""
    poses: dict[str, Any] = {}

    def ask() -> bool:
        for r in fab.rpc.query(keys.srv(world, "world"), timeout=5.0, expected=WorldInfo, all_replies=True):
            poses.update({x.id: x.pose for x in r.message.robots if facts(x.kind).chain})
        return all(f"arm{k}" in poses for k in range(arms))

    wait_until(ask, timeout=60, what="the arms' spawn poses", seen=lambda: sorted(poses))
    out = []
    for k in range(arms):
        x, y, z, yaw = (float(v) for v in poses[f"arm{k}"][:4])
        out.append(f"{x + 0.2 * math.cos(yaw):.3f},{y + 0.2 * math.sin(yaw):.3f},{z + 0.3:.3f}")
    return ";".join(out)


def _owners(fab: Any, bases: int, arms: int) -> tuple[dict[int, Any], dict[str, str | None]]:
    """Each base's record (by number) and each arm's owner, from a replica of the authority's records."""
    from ownership.client import OwnershipClient

    own = OwnershipClient(fab, "probe")  # a replica of the records (the probe owns nothing)
    try:
        own.refresh()
        records = {i: own.record(f"base{i}") for i in range(bases)}
        arm_owners = {f"arm{k}": (r.owner if (r := own.record(f"arm{k}")) is not None else None) for k in range(arms)}
    finally:
        own.close()
    return records, arm_owners


def _end_class(procs: Any, proc: Any) -> dict[str, Any]:
    """Stop the emulated students (SIGTERM: each lets go of ← and reads her page once more); their report."""
    import json
    import signal

    proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(timeout=60)
    except Exception:
        proc.kill()
    for ln in reversed(procs.output(proc).splitlines()):
        if ln.startswith("{"):
            return dict(json.loads(ln))
    return {
        "clients": 0,
        "joined": 0,
        "join_s": [],
        "keys": 0,
        "back_at_login": 0,
        "disconnected": 0,
        "refused": 0,
        "errors": [f"no report: {procs.output(proc)[-300:]}"],
    }


def run_one(
    n: int,
    seconds: float,
    tmp: Path,
    *,
    swiftshader: bool = False,
    robots: int = 0,
    together: bool = False,
    clients: int = 0,
    arms: int = 0,
    one_address: bool = False,
    no_3d: bool = False,
    view_fps: int = 10,
) -> dict[str, Any]:
    """N pages on one console (and ``clients`` emulated students beside them), in a world of
    ``max(n + clients, robots)`` bases; the row's figures."""
    from playwright.sync_api import sync_playwright

    import numpy as np

    from fabric.interfaces import JointState, Pose
    from robofabric.testing import ProcessGroup, client, free_port, robofabric_cmd, wait_until
    from robofabric.bench.viewer_web import CHROMIUM
    from user_peer.console.health import parse_line

    world = f"con{uuid.uuid4().hex[:6]}"
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    logs = tmp / f"n{n}"
    logs.mkdir(parents=True, exist_ok=True)
    with ProcessGroup(logs) as procs:
        router = procs.start(robofabric_cmd("router", "--world", world, "--listen", ep), name="router")
        wait_until(
            lambda: "listening" in procs.output(router),
            timeout=60,
            what="the router",
            seen=lambda: procs.output(router),
        )
        spawn = [x for i in range(max(n + clients, robots)) for x in ("--robot", f"reeman:base{i}")]
        spawn += [x for j in range(arms) for x in ("--robot", f"meca500:arm{j}")]
        sim = procs.start(
            robofabric_cmd(
                "sim",
                "--scene",
                "warehouse",
                "--no-scene-robots",
                *spawn,
                "--world",
                world,
                "--connect",
                ep,
                "--id",
                "sim",
            ),
            name="sim",
        )
        if arms:  # the arms' students apply IK: the compute peer solves it
            compute = procs.start(robofabric_cmd("compute", "--world", world, "--connect", ep), name="compute")
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
                *(["--no-3d"] if no_3d else []),
                "--view-fps",
                str(view_fps),
            ),
            name="console",
        )
        url = f"http://127.0.0.1:{web}/"
        wait_until(
            lambda: f"console: open {url}" in procs.output(console),
            timeout=60,
            what="the console",
            seen=lambda: procs.output(console)[-1500:],
        )
        turning: dict[int, list[int]] = {i: [] for i in range(n + clients)}  # sim wall stamps (ns) of poses that turn

        def on_pose(key: str, msg: Any) -> None:
            if isinstance(msg, Pose) and abs(float(msg.angular[2])) > 0.05:
                rid = key.split("/")[3]
                if rid.startswith("base") and rid[4:].isdigit() and int(rid[4:]) < n + clients:
                    turning[int(rid[4:])].append(msg.header.wall_ns)

        with client(world, port, kind="tool", peer_id="probe") as fab, sync_playwright() as p:
            wait_until(
                lambda: fab.live_peers("sim"), timeout=120, what="the sim", seen=lambda: procs.output(sim)[-1500:]
            )
            if arms:
                wait_until(
                    lambda: fab.live_peers("compute"),
                    timeout=120,
                    what="the compute peer",
                    seen=lambda: procs.output(compute)[-1500:],
                )
            fab.subscribe(f"rf/{world}/robot/*/pose", on_pose)
            arm_q: dict[str, list[Any]] = {}  # each arm's first and latest joint positions

            def on_joints(key: str, msg: Any) -> None:
                seen = arm_q.setdefault(key.split("/")[3], [None, None])
                seen[0] = msg.q if seen[0] is None else seen[0]
                seen[1] = msg.q

            if arms:
                fab.subscribe(f"rf/{world}/robot/arm$*/joints", on_joints, expected=JointState)
            browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=browser_args(swiftshader))
            reloads: list[str] = []  # NiceGUI's own words when a page reloads itself (connection timed out, ...)
            klass = (
                _start_class(
                    procs, url, n, clients, 10 * seconds + 600, arms, _arm_targets(fab, world, arms), one_address
                )
                if clients
                else None
            )
            klass_t0 = time.monotonic()
            try:
                pages, bases, joined, join_cpu = _open_pages(browser, url, n, reloads, together=together)
                lags: list[float] = []
                presses: list[float] = []
                missed = unstopped = 0
                cpu0, browsers0, t0 = proc_cpu_s(console.pid), chromium_cpu_s(os.getpid()), time.monotonic()
                # the rest of the box while the pages drive: what a class's world leaves the browsers and the server
                others = {"sim": sim, "router": router, **({"class": klass} if klass is not None else {})}
                others0 = {name: proc_cpu_s(pr.pid) for name, pr in others.items()}
                # how full the box was, and what each of the world's processes waited for a CPU: a server short of
                # CPU on a full box, or one that has it and is slow, read the same in its CPU time alone
                box0 = box_idle_s()
                waiting = {"console": console, **others}
                waited0 = {name: proc_waited_s(pr.pid) for name, pr in waiting.items()}
                health_from = len(procs.output(console))
                k = 0
                while pages and time.monotonic() - t0 < seconds:
                    page, i = pages[k % len(pages)], bases[k % len(pages)]
                    k += 1
                    now_ms, stamp_ms = page.evaluate(LAG_JS)
                    if stamp_ms:
                        lags.append((now_ms - stamp_ms) / 1e3)
                    page.keyboard.up("ArrowLeft")
                    let_go = time.time_ns()
                    # still: no turning pose for 0.3 s (a base still turning after 10 s is counted, and pressed anyway)
                    if not _until(
                        lambda: time.time_ns() - max(turning[i][-1] if turning[i] else 0, let_go) > 300_000_000, 10.0
                    ):
                        unstopped += 1
                    pressed = time.time_ns()
                    page.keyboard.down("ArrowLeft")
                    first = _until(lambda: next((s for s in turning[i] if s > pressed), None), 5.0)
                    if first is None:
                        missed += 1  # a press that did not move its base within 5 s
                    else:
                        presses.append((first - pressed) / 1e9)
                if not pages:  # no page got in: the class drives alone, and the server's CPU is still measured
                    time.sleep(seconds)
                took = time.monotonic() - t0
                cpu = (proc_cpu_s(console.pid) - cpu0) / took
                browsers1 = chromium_cpu_s(os.getpid())
                page_cpu, renderer_cpu = _per_page(browsers0, browsers1, took, len(pages))
                print(
                    f"  browsers while driving (cores, all pages): {_by_kind(browsers0, browsers1, took)}",
                    file=sys.stderr,
                    flush=True,
                )
                print(
                    "  the others while driving (cores): "
                    + ", ".join(
                        f"{name} {(proc_cpu_s(pr.pid) - others0[name]) / took:.2f}" for name, pr in others.items()
                    ),
                    file=sys.stderr,
                    flush=True,
                )
                box1 = box_idle_s()
                busy = 1 - (box1[1] - box0[1]) / max(box1[0] - box0[0], 1e-9)
                waited = {name: (proc_waited_s(pr.pid) - waited0[name]) / took for name, pr in waiting.items()}
                print(
                    f"  the box while driving: {busy:.0%} busy; runnable and waiting for a CPU (thread-s a second): "
                    + ", ".join(f"{name} {w:.2f}" for name, w in waited.items()),
                    file=sys.stderr,
                    flush=True,
                )
                health = [h for h in map(parse_line, procs.output(console)[health_from:].splitlines()) if h is not None]
                messages = [_status(pg) for pg in pages]
                for pg in pages:
                    pg.keyboard.up("ArrowLeft")
                # who owns what while every page and student is still there: read once they had left, a slow close
                # (past the console's 10 s grace) counted every robot its grace had passed on as lost
                records, arm_owners = _owners(fab, n + clients, arms)
            finally:
                browser.close()
                # the emulated students' own process, joins included: what the class's emulation costs this box
                klass_cpu = proc_cpu_s(klass.pid) / max(time.monotonic() - klass_t0, 1e-9) if klass is not None else 0.0
                emulated = _end_class(procs, klass) if klass is not None else None
    lost = sum(1 for i, r in records.items() if i in bases and (r is None or r.owner != f"s{i}"))
    if emulated is not None:  # a student of the class who got in and whose base no longer names her
        lost += sum(
            1
            for i in range(n, n + clients)
            if f"c{i}" in emulated.get("owners", ()) and (records[i] is None or records[i].owner != f"c{i}")
        )
        lost += sum(
            1 for k in range(arms) if f"arm{k}" in emulated.get("arms", ()) and arm_owners[f"arm{k}"] != f"c{n + k}"
        )
    refused = sum(1 for m in messages if m is not None and any(w in m for w in REFUSED))
    logged_out = sum(1 for m in messages if m is None)
    em = emulated or {}
    return {
        "n": n,
        "clients": clients,
        "c_joined": em.get("joined", 0),
        "c_join_max": max(em.get("join_s") or [float("nan")]),
        "c_back": em.get("back_at_login", 0),
        "c_dropped": em.get("disconnected", 0),
        "c_refused": em.get("refused", 0),
        "c_keys": em.get("keys", 0),
        "c_cpu": klass_cpu,
        "c_turned": sum(1 for i in range(n, n + clients) if turning[i]),
        "arms": arms,
        "c_arms": len(em.get("arms", [])),
        "c_ik": em.get("ik_applied", 0),
        "c_ik_unsolved": em.get("ik_unsolved", 0),
        "arms_moved": sum(
            1
            for a, b in arm_q.values()
            if a is not None and float(np.max(np.abs(np.asarray(b) - np.asarray(a)))) > 1e-3
        ),
        "c_errors": em.get("errors", []),
        "robots": max(n + clients, robots),
        "joined": len(joined),
        "join_max": max(joined, default=float("nan")),
        "lag_p50": pct(lags, 50),
        "lag_max": pct(lags, 100),
        "key_p50": pct(presses, 50, 1e3),
        "key_p99": pct(presses, 99, 1e3),
        "presses": len(presses),
        "missed": missed,
        "unstopped": unstopped,
        "cpu": cpu,
        "page_cpu": page_cpu,
        "renderer_cpu": renderer_cpu,
        "join_cpu": pct([x for x in join_cpu if x == x], 50),
        "lost": lost,
        "busy": busy,  # the box's CPUs while driving: 1.0 is a full box
        "waited": waited,  # per process: its threads' seconds runnable and waiting for a CPU, a second
        "refused": refused,
        "logged_out": logged_out,
        "reloads": len(reloads),
        "late_p99": max((h.late_p99 for h in health), default=float("nan")),
        "late_max": max((h.late_max for h in health), default=float("nan")),
        "to_server_p99": max((h.to_server_p99 for h in health), default=float("nan")),
        "to_sent_p99": max((h.to_sent_p99 for h in health), default=float("nan")),
    }


def header() -> list[str]:
    return [
        "| pages | joined (slowest, s) | view lag in the page p50 / max (s) | key to motion p50 / p99 (ms), presses "
        "| presses that moved nothing in 5 s / releases not stopped in 10 s | console server CPU (cores) | browsers per page driving, all / renderers (cores); a page's join, its renderer (CPU s, median) | robots lost | refused "
        "| pages back at the login (reloads) | server's event loop late p99 / max (ms) | key to server / to zenoh p99 (ms) "
        "| emulated students: joined (slowest, s), back at the login / dropped / refused, keys; their process (cores) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]


def row(r: dict[str, Any]) -> str:
    pages = (
        f"{r['n']} ({r['robots']} robots)" if r.get("robots", r["n"]) != r["n"] + r.get("clients", 0) else f"{r['n']}"
    )
    return (
        f"| {pages} | {r['joined']} ({r['join_max']:.1f}) | {r['lag_p50']:.2f} / {r['lag_max']:.2f} | "
        f"{r['key_p50']:.0f} / {r['key_p99']:.0f}, {r['presses']} | {r['missed']} / {r['unstopped']} | {r['cpu']:.2f} | {r['page_cpu']:.2f} / {r['renderer_cpu']:.2f}; {r['join_cpu']:.1f} | {r['lost']} | "
        f"{r['refused']} | {r['logged_out']} ({r['reloads']}) | {r['late_p99']:.0f} / {r['late_max']:.0f} | {r['to_server_p99']:.0f} / {r['to_sent_p99']:.0f} | "
        + (
            f"{r['c_joined']} of {r['clients']} ({r['c_join_max']:.1f}), {r['c_back']} / {r['c_dropped']} / {r['c_refused']}, "
            f"{r['c_keys']}"
            + (
                f", IK applied {r['c_ik']}, unsolved {r['c_ik_unsolved']} (arms moved {r['arms_moved']} of {r['arms']})"
                if r.get("arms")
                else ""
            )
            + f"; {r['c_cpu']:.2f} |"
            if r.get("clients")
            else "none |"
        )
    )


def command(
    pages: Annotated[
        str, typer.Option("--pages", help="Comma-separated page counts (each page: one student, one base).")
    ] = "1,10,20",
    seconds: Annotated[float, typer.Option("--seconds", help="How long the pages drive while measured (s).")] = 30.0,
    out: Annotated[Optional[Path], typer.Option("--out", help="Append the markdown table to this file.")] = None,
    swiftshader: Annotated[
        bool,
        typer.Option(
            "--swiftshader",
            help="The tests' Chromium flags (as the Rerun viewer's benchmark): WebGL forced through SwiftShader's "
            "software GL, the pages composited on the CPU; not as Chromium chooses.",
        ),
    ] = False,
    robots: Annotated[
        int,
        typer.Option(
            "--robots",
            help="Bases in the world (at least one a page): a few pages in a "
            "class-sized world measure the server's cost per page without a class of browsers.",
        ),
    ] = 0,
    together: Annotated[
        bool,
        typer.Option("--together", help="Ask for every page at once, as a class does, instead of one after another."),
    ] = False,
    clients: Annotated[
        int,
        typer.Option(
            "--clients",
            help="Emulated students beside the pages: each speaks the page's "
            "own socket protocol with no browser, logs in, requests her base and steers it "
            "(python -m robofabric.bench.console_client).",
        ),
    ] = 0,
    arms: Annotated[
        int,
        typer.Option(
            "--arms",
            help="Meca500 arms in the world (and a compute peer for their IK): the "
            "first ARMS emulated students also own one and nudge its target and apply IK.",
        ),
    ] = 0,
    one_address: Annotated[
        bool,
        typer.Option(
            "--one-address",
            help="Every emulated student from 127.0.0.1, as a class "
            "behind one NAT, instead of each from her own 127.0.0.N.",
        ),
    ] = False,
    no_3d: Annotated[
        bool,
        typer.Option(
            "--no-3d",
            help="The console's pages without their 3D view (console --no-3d): "
            "the 2D page, beside the same run with it.",
        ),
    ] = False,
    view_fps: Annotated[
        int,
        typer.Option(
            "--view-fps",
            help="Frames a second each page's 3D view draws (console --view-fps): a page driving its base, drawn "
            "in software GL, cost its browser 1.10 of a core at 10 and 0.64 at 2 (docs/console.md).",
        ),
    ] = 10,
    logs: Annotated[
        Optional[Path],
        typer.Option(
            "--logs",
            help="Keep every process's output (router, sim, console, the class) in DIR/n<PAGES>/, not in a "
            "temporary folder removed at the end: what the console said of a lost robot's renewals.",
        ),
    ] = None,
) -> None:
    """N browser pages on one console server, each driving its own base: view lag in the page, key to motion,
    the server's CPU, robots lost."""
    import contextlib
    import tempfile

    from fabric.cli_common import UserError

    try:
        counts = [int(x) for x in pages.split(",") if x.strip()]
    except ValueError:
        raise UserError(f"--pages {pages!r}: expected counts like 1,10,20") from None
    if not counts or min(counts) < 1 or seconds <= 0 or robots < 0 or clients < 0 or not 0 <= arms <= clients:
        raise UserError(
            "--pages: each count at least 1; --seconds positive; --robots and --clients not negative; "
            "--arms from 0 to --clients (each arm is an emulated student's)"
        )
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    flag = (
        (" --swiftshader" if swiftshader else "")
        + (f" --robots {robots}" if robots else "")
        + (" --together" if together else "")
        + (f" --clients {clients}" if clients else "")
        + (f" --arms {arms}" if arms else "")
        + (" --one-address" if one_address else "")
        + (" --no-3d" if no_3d else "")
        + (f" --view-fps {view_fps}" if view_fps != 10 else "")
    )
    lines = [
        f"robofabric bench console --pages {pages} --seconds {seconds:g}{flag} on {machine()}, load average {load:.1f} at the start",
        "",
        *header(),
    ]
    print("\n".join(lines), flush=True)
    kept = contextlib.nullcontext(str(logs)) if logs is not None else None
    with kept or tempfile.TemporaryDirectory(prefix="bench-console-") as tmp:
        for n in counts:
            result = run_one(
                n,
                seconds,
                Path(tmp),
                swiftshader=swiftshader,
                robots=robots,
                together=together,
                clients=clients,
                arms=arms,
                one_address=one_address,
                no_3d=no_3d,
                view_fps=view_fps,
            )
            for err in result.get("c_errors", [])[:5]:
                print(f"  {err}", file=sys.stderr, flush=True)
            line = row(result)
            print(line, flush=True)
            lines.append(line)
    append(out, "\n".join(lines))
