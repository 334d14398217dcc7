"""What the console shares between its pages: every robot's pose read at the redraw (a page's own session,
zenoh's ring), decoded and drawn once for the pages that hold the same bytes, on one clock for all pages.

A real router and real sessions on loopback; no browser (test_console_browser.py shows the whole page)."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from fabric import keys
from fabric.codec import encode
from fabric.interfaces import Pose
from robofabric.testing import wait_until
from user_peer.console import topview
from user_peer.console.feed import Decoded, PoseFeed, ring_capacity
from user_peer.console.ticker import OnePerTurn, Ticker, next_due


def _pose(x: float) -> Pose:
    return Pose(position=np.array([x, 0.0, 0.0]))


def test_a_pages_feed_holds_every_robots_newest_pose_and_takes_no_more_than_its_ring(world, connect):
    """Poses published faster than the page redraws stay in zenoh's ring: the redraw takes at most a ring of them
    (not every sample), and finds the newest pose of every robot."""
    sim, page, counter = connect("sim", "sim"), connect("user", "alice"), connect("tool", "counter")
    robots = [f"base{i}" for i in range(3)]
    feed = PoseFeed(page, world, ring_capacity(len(robots)))
    heard: list[str] = []
    counter.subscribe_raw(keys.robot_stream_all(world, "pose"), lambda s: heard.append(str(s.key_expr)))

    def both_listen() -> bool:  # the subscriptions reached the router: a warm-up pose gets through to both
        sim.publish(keys.robot_stream(world, "base0", "pose"), _pose(-1.0))
        return "base0" in feed.drain() and bool(heard)

    wait_until(both_listen, timeout=20, what="the page's feed and the counter to hear a pose")
    heard.clear()
    taken = feed.taken
    bursts = 40
    for b in range(bursts):
        for rid in robots:
            sim.publish(keys.robot_stream(world, rid, "pose"), _pose(float(b)))
    wait_until(
        lambda: len(heard) >= bursts * len(robots),
        timeout=20,
        what="every pose at another session",
        seen=lambda: len(heard),
    )

    def newest() -> bool:
        raw = feed.drain()
        return set(raw) == set(robots) and all(Decoded().pose(r, raw[r]).position[0] == bursts - 1 for r in robots)

    wait_until(
        newest, timeout=20, what="the newest pose of every robot in the page's feed", seen=lambda: sorted(feed.raw)
    )
    assert feed.taken - taken <= 2 * ring_capacity(len(robots)) < bursts * len(robots), feed.taken - taken
    feed.close()
    assert feed.drain() == feed.raw  # a closed feed keeps what it had and reads nothing


def test_the_same_bytes_decode_once_and_draw_once_per_way_of_drawing():
    d = Decoded()
    a, b = encode(_pose(1.0)), encode(_pose(2.0))
    assert d.pose("base1", a).position[0] == 1.0 and d.pose("base1", bytes(a)).position[0] == 1.0
    assert d.decoded == 1  # the second page's equal bytes were not decoded again
    assert d.pose("base1", b).position[0] == 2.0 and d.decoded == 2
    drawn: list[tuple] = []

    def draw(variant):
        return lambda pose: drawn.append((variant, pose.position[0])) or f"<{variant}:{pose.position[0]}>"

    assert d.drawn("base1", b, "mine", draw("mine")) == "<mine:2.0>"
    assert d.drawn("base1", bytes(b), "mine", draw("mine")) == "<mine:2.0>"
    assert d.drawn("base1", b, "other", draw("other")) == "<other:2.0>"
    assert drawn == [("mine", 2.0), ("other", 2.0)]


def test_bytes_that_are_no_pose_are_counted_and_draw_as_nothing():
    d = Decoded()
    assert d.pose("base1", b"\x00not a pose") is None and d.bad == 1
    assert d.drawn("base1", b"\x00not a pose", "v", lambda pose: "" if pose is None else "drawn") == ""


def test_the_clock_calls_every_page_once_a_tick_and_one_that_fails_stops_no_other():
    t = Ticker(0.01)
    calls: list[str] = []
    a = t.add(lambda: calls.append("a"))
    t.add(lambda: 1 / 0)
    t.add(lambda: calls.append("c"))
    t.tick()
    assert calls == ["a", "c"] and t.failed == 1
    t.remove(a)
    t.tick()
    assert calls == ["a", "c", "c"] and len(t) == 2


def test_the_clock_runs_on_the_event_loop_until_cancelled():
    t = Ticker(0.01)
    seen: list[int] = []
    t.add(lambda: seen.append(t.ticks))

    async def main() -> None:
        await _run_until(t, lambda: len(seen) >= 3)

    asyncio.run(main())
    assert seen[:3] == [1, 2, 3]


def test_the_clocks_pass_lets_the_event_loop_turn_between_two_pages_and_skips_one_that_left():
    """A pass over a class took seconds as one call of the loop: every socket's ping and key waited for it."""
    t = Ticker(0.01)
    order: list[str] = []
    handles: dict[str, int] = {}
    handles["a"] = t.add(lambda: order.append("a"))
    handles["b"] = t.add(lambda: (order.append("b"), t.remove(handles["c"])))  # c's page leaves during the pass
    handles["c"] = t.add(lambda: order.append("c"))
    handles["d"] = t.add(lambda: order.append("d"))

    _turn_beside_the_loop(t, order)
    pages = [x for x in order if x != "loop"]
    assert pages == ["a", "b", "d"] and t.ticks == 1
    assert (
        order.index("loop", order.index("a"))
        < order.index("b")
        < order.index("loop", order.index("b"))
        < order.index("d")
    )


def test_a_pass_takes_every_pages_samples_before_it_redraws_any_page():
    """A pass that lets the loop turn outlasts the sim's 20 ms between two poses: pages that took their samples as
    their turn came held newer bytes than the first, and each decoded and drew every robot again."""
    t = Ticker(0.01)
    order: list[str] = []
    handles = {
        p: t.add(lambda p=p: order.append(f"redraw {p}"), take=lambda p=p: order.append(f"take {p}")) for p in "abc"
    }
    t.add(lambda: order.append("redraw d"))  # a page with nothing to take
    t.tick()
    assert order == ["take a", "take b", "take c", "redraw a", "redraw b", "redraw c", "redraw d"]
    order.clear()
    t.remove(handles["b"])

    _turn_beside_the_loop(t, order)
    pages = [x for x in order if x != "loop"]
    assert pages == ["take a", "take c", "redraw a", "redraw c", "redraw d"]
    assert order.index("loop") < order.index("redraw c")  # the takes in one go, the redraws one per turn
    assert "loop" not in order[order.index("take a") : order.index("take c")]


def test_what_pages_make_of_the_same_bytes_is_made_once_per_variant():
    d = Decoded()
    a, b = encode(_pose(1.0)), encode(_pose(2.0))
    made: list[tuple[str, float]] = []

    def place(pose):
        made.append(("3d", pose.position[0]))
        return (pose.position[0], [[1.0]])

    first = d.derived("base1", a, "3d", place)
    assert d.derived("base1", bytes(a), "3d", place) is first and made == [("3d", 1.0)]
    assert d.derived("base1", b, "3d", place)[0] == 2.0 and d.decoded == 2
    assert d.derived("base1", b"\x00not a pose", "3d", lambda pose: pose) is None  # kept as made: None is an answer


def test_a_pass_longer_than_half_a_period_is_followed_by_as_long_a_rest():
    """The clock takes at most half the loop's time: the rest (sockets, keys, builds) gets the other half."""
    assert next_due(10.0, 0.2, 10.0, 10.05) == 10.2  # a short pass: the next a period after the last was due
    assert next_due(10.0, 0.2, 10.0, 10.1) == 10.2  # half a period: still on time
    assert next_due(10.0, 0.2, 10.0, 10.3) == pytest.approx(10.6)  # 0.3 s of pass: 0.3 s of rest after it
    assert next_due(10.0, 0.2, 10.05, 10.2) == pytest.approx(10.35)  # begun late: its rest counts from its end


def test_the_clock_rests_after_a_long_pass():
    t = Ticker(0.01)
    starts: list[float] = []

    async def main() -> None:
        loop = asyncio.get_running_loop()

        def slow() -> None:  # 30 ms of redraw each pass, a period of 10 ms
            starts.append(loop.time())
            end = loop.time() + 0.03
            while loop.time() < end:
                pass

        t.add(slow)
        await _run_until(t, lambda: len(starts) >= 4)

    asyncio.run(main())
    gaps = [b - a for a, b in zip(starts, starts[1:])]
    assert len(gaps) >= 3 and min(gaps) >= 0.06 - 0.002, gaps  # 30 ms of pass, then at least 30 ms of rest
    assert t.stretched >= 3 and t.last_pass_s >= 0.03


def test_pages_ready_to_build_in_the_same_turn_build_one_per_turn_of_the_event_loop():
    """32 logins answered together were 32 builds run back to back in one turn: the loop stood still 17-43 s."""
    builds = OnePerTurn()
    order: list[str] = []

    async def build(name: str) -> str:
        return await builds.run(lambda: order.append(name) or name)

    async def other() -> None:
        for _ in range(8):
            order.append("loop")
            await asyncio.sleep(0)

    async def main() -> list:
        return await asyncio.gather(build("a"), build("b"), build("c"), other())

    assert asyncio.run(main())[:3] == ["a", "b", "c"]
    at = [i for i, x in enumerate(order) if x != "loop"]
    assert [order[i] for i in at] == ["a", "b", "c"]
    assert all("loop" in order[i + 1 : j] for i, j in zip(at, at[1:]))  # the loop turned between two builds


def test_every_page_starts_on_the_same_picture_of_the_scene_drawn_once():
    f = topview.Frame(0.0, 0.0, 4.0, 4.0, 10.0)
    first = topview.background_png(f, [(1.0, 1.0, 0.5, 0.2, 0.0)])
    assert topview.background_png(f, [(1.0, 1.0, 0.5, 0.2, 0.0)]) is first  # the same bytes, not drawn again
    assert topview.background_png(f, [(1.0, 1.0, 0.5, 0.2, 0.5)]) != first  # another scene is its own picture


def test_a_scan_is_one_path_of_squares_one_per_pixel_hit():
    f = topview.Frame(-5, -5, 5, 5)
    scan = np.array([[1.0, 1.0], [1.001, 1.001], [-2.0, 0.5]])  # the first two fall in the same pixel
    out = topview.scan_path(f, scan)
    assert out.count("<path") == 1 and out.count("h2v2h-2z") == 2
    x, y = f.px(1.0, 1.0)
    assert f"M{round(x) - 1} {round(y) - 1}h2v2h-2z" in out


def _turn_beside_the_loop(t, order: list[str]) -> None:
    """One turn of the clock while another task of the loop runs three steps, each step written as "loop"."""

    async def other() -> None:
        for _ in range(3):
            order.append("loop")
            await asyncio.sleep(0)

    async def main() -> None:
        await asyncio.gather(t.turn(), other())

    asyncio.run(main())


async def _run_until(t: Ticker, done, steps: int = 4000) -> None:
    """Run the clock on this loop until ``done()`` (looked at every 5 ms, at most ``steps`` times), then cancel it."""
    task = asyncio.ensure_future(t.run())
    for _ in range(steps):
        if done():
            break
        await asyncio.sleep(0.005)
    task.cancel()
