"""Browsers on one ``robofabric view --serve-web``: how far behind live each page is, measured from the page.

The page's own measure: its viewer's time cursor on the ``wall_time`` timeline (the page follows live, so
the cursor is the newest data the page has taken in) against the page's ``Date.now()``, both read in one
``page.evaluate`` from ``window.rerun_handle.viewer_state()`` (the page user_peer/web_page.py serves
exposes its handle; the state is Rerun's encoded ``GetStateResponse``, read here without its schema: the
time cursor is the one integer field that holds nanoseconds since 1970 within an hour of now). The viewer
and the browsers run on one machine, so one clock.

Pages are opened in Debian's headless ``chromium`` (software WebGL) through ``playwright``; ``stalled``
further pages have their JavaScript paused (CDP ``Debugger.pause``) once they show the world: they stop
taking data, as a student's laptop that went to sleep.
"""

from __future__ import annotations

import re
import time
from typing import Any

CHROMIUM = "/usr/bin/chromium"
# WebGL drawn by SwiftShader (software GL, no GPU here), the page composited by the CPU: composited through
# SwiftShader too, every repaint (a text changing five times a second) cost the GPU process a whole frame of
# software GL: a console page, driving its base, took 0.59 of a core, 0.21 composited by the CPU, its 3D view
# drawn as before (docs/testing.md, "Chromium composites on the CPU")
CHROMIUM_ARGS = [
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-gpu-compositing",
    "--no-sandbox",
    "--headless",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--disable-background-timer-throttling",
    "--disable-renderer-backgrounding",
    "--disable-backgrounding-occluded-windows",
]
STATE_JS = (
    "() => { const h = window.rerun_handle; if (!h) return [Date.now(), null]; "
    "try { return [Date.now(), Array.from(h.viewer_state())]; } catch (e) { return [Date.now(), null]; } }"
)

__all__ = ["CHROMIUM", "CHROMIUM_ARGS", "page_lag", "varints_ns", "open_pages", "measure"]


def _fields(buf: bytes, depth: int = 0):
    """Every varint and fixed64 in a protobuf message, nested messages included (best effort, no schema)."""
    i, n = 0, len(buf)
    while i < n:
        key, i = _varint(buf, i)
        if key is None:
            return
        wt = key & 7
        if wt == 0:
            v, i = _varint(buf, i)
            if v is None:
                return
            yield v
        elif wt == 1:
            if i + 8 > n:
                return
            yield int.from_bytes(buf[i : i + 8], "little", signed=True)
            i += 8
        elif wt == 2:
            ln, i = _varint(buf, i)
            if ln is None or i + ln > n:
                return
            if depth < 8:
                yield from _fields(buf[i : i + ln], depth + 1)
            i += ln
        elif wt == 5:
            i += 4
        else:
            return


def _varint(buf: bytes, i: int) -> tuple[int | None, int]:
    shift = v = 0
    while i < len(buf):
        b = buf[i]
        i += 1
        v |= (b & 0x7F) << shift
        if not b & 0x80:
            return v, i
        shift += 7
        if shift > 63:
            return None, i
    return None, i


def varints_ns(state: bytes, now_ms: float) -> list[int]:
    """The integers of ``state`` that read as nanoseconds since 1970 within an hour of ``now_ms``."""
    lo, hi = int((now_ms - 3.6e6) * 1e6), int((now_ms + 3.6e6) * 1e6)
    return [v for v in _fields(state) if lo <= v <= hi]


def page_lag(page: Any) -> float | None:
    """How far (s) the page's view is behind the page's clock: None before it shows data of the live world."""
    now_ms, state = page.evaluate(STATE_JS)
    if not state:
        return None
    times = varints_ns(bytes(state), now_ms)
    if not times:
        return None
    return now_ms / 1e3 - max(times) / 1e9


def page_fps(page: Any, seconds: float = 3.0) -> float:
    """The page's animation frames per second over ``seconds`` (the pace its viewer draws, and takes in data, at)."""
    return page.evaluate(
        """(ms) => new Promise(done => { let n = 0; const t0 = performance.now();
        function tick(t) { n++; if (t - t0 < ms) requestAnimationFrame(tick); else done(n * 1000 / (t - t0)); }
        requestAnimationFrame(tick); })""",
        seconds * 1000,
    )


def open_pages(browser: Any, url: str, n: int, viewport: dict[str, int]) -> list[Any]:
    pages = []
    for _ in range(n):
        ctx = browser.new_context(viewport=viewport)
        page = ctx.new_page()
        page.goto(url, timeout=120_000)
        pages.append(page)
    return pages


def measure(
    url: str,
    pages: int,
    stalled: int = 0,
    seconds: float = 60.0,
    viewport: dict[str, int] | None = None,
    warmup_s: float = 180.0,
    every_s: float = 2.0,
    log: Any = print,
    shot: str | None = None,
) -> dict[str, Any]:
    """Open ``pages`` + ``stalled`` pages on ``url``; once every page shows the live world, pause the
    ``stalled`` ones and sample every live page's lag for ``seconds``. Returns per page lists of lags (s)."""
    from playwright.sync_api import sync_playwright

    viewport = viewport or {"width": 1280, "height": 800}
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS)
        try:
            all_pages = open_pages(browser, url, pages + stalled, viewport)
            deadline = time.monotonic() + warmup_s
            while True:
                lags = [page_lag(pg) for pg in all_pages]
                if all(lag is not None for lag in lags) or time.monotonic() > deadline:
                    break
                all_pages[0].wait_for_timeout(1000)
            ready = time.monotonic() - (deadline - warmup_s)
            log(
                f"pages showing the world after {ready:.0f} s: {sum(lag is not None for lag in lags)}/{len(lags)}; lags {lags}"
            )
            frozen = all_pages[pages:]
            for pg in frozen:
                cdp = pg.context.new_cdp_session(pg)
                cdp.send("Debugger.enable")
                cdp.send("Debugger.pause")
            live = all_pages[:pages]
            series: list[list[float | None]] = [[] for _ in live]
            t_end = time.monotonic() + seconds
            while time.monotonic() < t_end:
                t0 = time.monotonic()
                for i, pg in enumerate(live):
                    series[i].append(page_lag(pg))
                log(" ".join("-" if s[-1] is None else f"{s[-1]:.2f}" for s in series))
                left = every_s - (time.monotonic() - t0)
                if left > 0:
                    live[0].wait_for_timeout(left * 1000)
            if shot:  # the first page as it looks, beside its measured lag (its top bar shows Rerun's own "latency")
                lag = page_lag(live[0])
                live[0].screenshot(path=shot)
                log(f"screenshot {shot}: page lag {lag if lag is None else round(lag, 2)} s")
            fps = [page_fps(pg) for pg in live]
            log(f"frames per second per live page: {[round(f, 1) for f in fps]}")
            return {
                "pages": pages,
                "stalled": stalled,
                "seconds": seconds,
                "ready_s": ready,
                "lags": series,
                "fps": fps,
            }
        finally:
            browser.close()


def summary(result: dict[str, Any]) -> dict[str, float]:
    vals = [v for s in result["lags"] for v in s if v is not None]
    missing = sum(v is None for s in result["lags"] for v in s)
    worst_last = max((s[-1] for s in result["lags"] if s and s[-1] is not None), default=float("nan"))
    vals.sort()

    def p(q: float) -> float:
        return vals[min(len(vals) - 1, int(q * len(vals)))] if vals else float("nan")

    return {
        "p50": p(0.5),
        "p90": p(0.9),
        "max": vals[-1] if vals else float("nan"),
        "last_worst": worst_last,
        "missing": missing,
    }


VIEWER_URL = re.compile(r"web viewer: open (http://\S+)")


def run(
    pages: int,
    stalled: int,
    seconds: float,
    width: int,
    view_args: list[str],
    log: Any = print,
    shot: str | None = None,
) -> dict[str, Any]:
    """A router, ``robofabric sim --scene combined`` and ``robofabric view --serve-web VIEW_ARGS`` as child
    processes, then :func:`measure`; every child ended by pid. Adds the viewer's last lines (relay cuts)."""
    import tempfile
    import uuid
    from pathlib import Path

    from robofabric.testing import ProcessGroup, free_port, robofabric_cmd, wait_until

    world = f"benchweb{uuid.uuid4().hex[:6]}"
    with tempfile.TemporaryDirectory(prefix="bench-web-") as tmp, ProcessGroup(Path(tmp)) as procs:
        ep = f"tcp/127.0.0.1:{free_port()}"
        router = procs.start(robofabric_cmd("router", "--listen", ep, "--world", world), name="router")
        wait_until(
            lambda: accepts(ep),
            timeout=30,
            interval=0.1,
            what="the router to listen",
            seen=lambda: procs.output(router),
        )
        sim = procs.start(robofabric_cmd("sim", "--scene", "combined", "--world", world, "--connect", ep), name="sim")
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
                "--world",
                world,
                "--connect",
                ep,
                *view_args,
            ),
            name="view",
        )
        url = wait_until(
            lambda: VIEWER_URL.search(procs.output(view)),
            timeout=90,
            interval=0.2,
            what="the viewer's URL",
            seen=lambda: (procs.output(router) + procs.output(sim) + procs.output(view))[-2000:],
        ).group(1)
        result = measure(url, pages, stalled, seconds, {"width": width, "height": width * 5 // 8}, log=log, shot=shot)
        result["view_log"] = procs.output(view)
        result["cut"] = re.findall(r"web relay: page \S+ cut off: (.*)", result["view_log"])
        result["blocked"] = result["view_log"].count("has been blocked")
    result.update(width=width, view_args=view_args)
    return result


def accepts(ep: str) -> bool:
    import socket

    host, port = ep.split("/", 1)[1].rsplit(":", 1)
    try:
        with socket.create_connection((host, int(port)), timeout=1):
            return True
    except OSError:
        return False


def main(argv: list[str] | None = None) -> None:
    """``python -m robofabric.bench.viewer_web --pages 10 --stalled 1 --seconds 60 --width 640 -- --window 0.5 --max-hz 5``"""
    import argparse

    from robofabric.bench.common import machine

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pages", type=int, default=10, help="live pages")
    ap.add_argument("--stalled", type=int, default=1, help="further pages paused once they show the world")
    ap.add_argument("--seconds", type=float, default=60.0, help="how long the live pages' lag is sampled")
    ap.add_argument("--width", type=int, default=1280, help="page width (height 5/8 of it)")
    ap.add_argument("--shot", help="save a screenshot of the first page here at the end")
    ap.add_argument("view_args", nargs="*", help="after --: options of robofabric view (e.g. --window 0.5 --max-hz 5)")
    a = ap.parse_args(argv)
    r = run(a.pages, a.stalled, a.seconds, a.width, a.view_args, shot=a.shot)
    s = summary(r)
    print(machine())
    print(
        f"{a.pages} live pages + {a.stalled} paused, {a.width}x{a.width * 5 // 8}, view {' '.join(a.view_args) or '(defaults)'}: "
        f"all showing the world after {r['ready_s']:.0f} s; lag over {a.seconds:g} s: p50 {s['p50']:.1f} s, p90 {s['p90']:.1f} s, "
        f"max {s['max']:.1f} s, worst page at the end {s['last_worst']:.1f} s; frames/s per page "
        f"{min(r['fps']):.1f}-{max(r['fps']):.1f}; paused pages cut off: {len(r['cut'])} ({'; '.join(r['cut'])}); "
        f"'sender blocked' reports: {r['blocked']}"
    )


if __name__ == "__main__":
    main()
