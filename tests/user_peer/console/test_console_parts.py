"""The console's pure parts: the top view's geometry and picture, the keys-to-twist rules, the logins' grace.

No browser, no router: the browser tests (test_console_browser.py) show the parts together."""

from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest

from robofabric.testing import free_port, wait_until
from user_peer.console import topview
from user_peer.console.drive import Driver, SPEEDS
from user_peer.console.login import LoginError, Logins, login_config
from user_peer.console.topview import Frame, RobotMark


def test_frame_maps_world_to_pixels_and_back():
    f = Frame(-5.0, -5.0, 5.0, 5.0, scale=40.0)
    assert (f.width, f.height) == (400, 400)
    assert f.px(-5.0, 5.0) == (0.0, 0.0)  # top left is north-west
    assert f.px(5.0, -5.0) == (400.0, 400.0)
    assert f.world(*f.px(1.25, -3.5)) == pytest.approx((1.25, -3.5))


def test_frame_around_is_square_and_holds_every_point():
    f = topview.frame_around([(0, 0), (6, 1)], margin=1.0, minimum=4.0)
    assert f.xmax - f.xmin == pytest.approx(f.ymax - f.ymin) == pytest.approx(8.0)
    assert f.xmin <= -1 and f.xmax >= 7 and f.ymin <= -1 and f.ymax >= 2
    assert topview.frame_around([], minimum=10.0).width == 400


def test_svg_draws_robots_with_their_owners_escaped():
    f = Frame(-5, -5, 5, 5)
    out = topview.svg(
        f,
        [
            RobotMark("base1", "mobile", "<script>", 1.0, 2.0, 0.0),
            RobotMark("arm1", "arm", "", 3.0, 0.0, 0.0, flange=(3.2, 0.0)),
        ],
        scan=np.array([[1.0, 1.0]]),
        paths=[np.array([[0, 0], [1, 1]])],
        target=(3.2, 0.0),
        goal=(1.0, 1.0, 0.5),
    )
    assert "<script>" not in out and "&lt;script&gt;" in out
    assert "base1 · &lt;script&gt;" in out and "arm1 · free" in out
    assert out.count("<polygon") == 1 and "<polyline" in out and 'fill="#f03e3e"' in out


def test_mine_and_others_robots_have_different_colours():
    f = Frame(-5, -5, 5, 5)
    mine = topview.svg(f, [RobotMark("b", "mobile", "alice", 0, 0, 0, mine=True)])
    other = topview.svg(f, [RobotMark("b", "mobile", "bob", 0, 0, 0)])
    free = topview.svg(f, [RobotMark("b", "mobile", "", 0, 0, 0)])
    assert topview.COLORS["mine"] in mine and topview.COLORS["other"] in other and topview.COLORS["free"] in free


def test_an_arm_followed_in_full_is_drawn_as_its_chain_of_links_from_its_spawn():
    from user_peer.console.state import arm_chain, arm_links

    q = np.zeros(6)
    origins = arm_chain("meca500").origins(q)
    links = arm_links("meca500", q, (1.0, 2.0, 0.5, np.pi / 2))  # spawned at (1, 2), turned a quarter left
    assert links[0] == (1.0, 2.0) and len(links) == len(origins) + 1
    x, y, _ = origins[-1]
    assert np.allclose(links[-1], (1.0 - y, 2.0 + x))  # the arm's +x is the world's +y
    assert arm_links("meca500", np.zeros(5), (0, 0, 0, 0)) == ()  # a joint vector that does not fit: nothing drawn
    assert arm_links("no-such-arm", q, (0, 0, 0, 0)) == ()
    f = Frame(0, 0, 10, 10)
    svg = topview.svg(f, [RobotMark("arm1", "arm", "", 1, 2, 0, links=links)])
    assert 'class="rf-arm-links"' in svg and svg.count("<circle") == len(links) - 1
    assert "rf-arm-links" not in topview.svg(f, [RobotMark("arm1", "arm", "", 1, 2, 0, flange=(1.2, 2.0))])


def test_scan_points_leave_out_rays_that_hit_nothing():
    pts = topview.scan_points(1.0, 0.0, np.pi / 2, 0.0, np.pi / 2, np.array([2.0, 5.0]), range_max=5.0)
    assert pts.shape == (1, 2)
    assert pts[0] == pytest.approx([1.0, 2.0])  # facing north, the first ray straight ahead


def _png_pixels(png: bytes) -> np.ndarray:
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    w, h = struct.unpack(">II", png[16:24])
    pos, idat = 8, b""
    while pos < len(png):
        n = struct.unpack(">I", png[pos : pos + 4])[0]
        kind = png[pos + 4 : pos + 8]
        if kind == b"IDAT":
            idat += png[pos + 8 : pos + 8 + n]
        pos += 12 + n
    raw = zlib.decompress(idat)
    rows = [raw[i * (w + 1) : (i + 1) * (w + 1)] for i in range(h)]
    assert all(r[0] == 0 for r in rows)
    return np.array([list(r[1:]) for r in rows], dtype=np.uint8)


def test_grid_png_puts_occupied_cells_where_the_frame_shows_them():
    cells = np.zeros((20, 20), dtype=np.uint8)  # 2 m x 2 m at 0.1 m, from (0, 0)
    cells[15, 5] = 100  # the cell at x 0.5..0.6, y 1.5..1.6
    cells[0, 0] = 255
    f = Frame(0.0, 0.0, 4.0, 4.0, scale=10.0)
    img = _png_pixels(topview.grid_png(cells, 0.1, (0.0, 0.0, 0.0), f))
    assert img.shape == (40, 40)
    col, row = f.px(0.55, 1.55)
    assert img[int(row), int(col)] == 0  # occupied: black
    assert img[int(f.px(0.05, 0.05)[1]), 0] == 230  # unknown: grey
    assert img[int(f.px(1.0, 1.0)[1]), 10] == 255  # free: white
    assert img[5, 35] == 230  # outside the map


def test_the_background_draws_the_scenes_boxes_once_under_the_map_s_occupied_cells():
    """The still picture holds the static boxes (turned by their yaw), so the overlay a page redraws need not;
    an occupied map cell inside a box stays black."""
    f = Frame(0.0, 0.0, 4.0, 4.0, scale=10.0)

    def at(img, x, y):
        col, row = f.px(x, y)
        return img[int(row), int(col)]

    flat = _png_pixels(topview.background_png(f, [(1.0, 1.0, 0.5, 0.2, 0.0)]))
    assert at(flat, 1.0, 1.0) == at(flat, 1.45, 1.15) == topview.BOX
    assert at(flat, 1.0, 1.35) == topview.UNKNOWN and at(flat, 3.0, 3.0) == topview.UNKNOWN
    turned = _png_pixels(topview.background_png(f, [(1.0, 1.0, 0.5, 0.2, np.pi / 2)]))
    assert at(turned, 1.0, 1.35) == topview.BOX and at(turned, 1.35, 1.0) == topview.UNKNOWN
    cells = np.zeros((40, 40), dtype=np.uint8)  # the whole frame known free, at 0.1 m
    cells[10, 10] = 100  # x 1.0..1.1, y 1.0..1.1: inside the box
    mapped = _png_pixels(topview.background_png(f, [(1.0, 1.0, 0.5, 0.2, 0.0)], (cells, 0.1, (0.0, 0.0, 0.0))))
    assert at(mapped, 1.05, 1.05) == 0 and at(mapped, 0.75, 1.05) == topview.BOX and at(mapped, 3.0, 3.0) == 255
    assert "<polygon" not in topview.svg(f, [])  # nothing still is left in the overlay unless asked for


def test_pictures_are_served_by_a_new_url_for_each_picture_and_are_bounded():
    """A page's picture has a URL a page cannot guess for another's, a new one with each new picture (the browser
    never shows a stale map), and the store forgets the oldest page past its limit."""
    from user_peer.console.pictures import ROUTE, Pictures

    pics = Pictures(limit=2)
    a, b = pics.new_token(), pics.new_token()
    assert a != b and len(a) >= 16
    first, second = pics.put(a, b"one"), pics.put(a, b"two")
    assert first.startswith(f"{ROUTE}/{a}.png?v=") and first != second and pics.get(a) == b"two"
    pics.put(b, b"bee")
    pics.put("c", b"sea")  # a third page: the oldest picture (a's) goes
    assert pics.get(a) is None and pics.get(b) == b"bee" and len(pics) == 2
    pics.drop(b)
    assert pics.get(b) is None


def test_arrows_drive_while_held_and_opposites_cancel():
    d = Driver()
    assert d.twist() == (0.0, 0.0)
    assert d.key("ArrowUp", True)
    assert d.twist() == (SPEEDS[1][0], 0.0)
    assert d.key("ArrowLeft", True) and d.twist() == (SPEEDS[1][0], SPEEDS[1][1])
    assert d.key("ArrowDown", True) and d.twist()[0] == 0.0
    assert not d.key("ArrowDown", True)  # already held: nothing new to send
    d.key("ArrowDown", False)
    d.key("ArrowLeft", False)
    assert d.key("3", True) and d.twist() == (SPEEDS[3][0], 0.0)
    assert d.key("ArrowUp", False) and d.twist() == (0.0, 0.0) and not d.driving
    assert not d.key("x", True) and not d.key("ArrowUp", False)


def test_space_and_a_lost_focus_stop():
    d = Driver()
    d.key("ArrowRight", True)
    assert d.twist()[1] < 0
    assert d.key(" ", True) and d.twist() == (0.0, 0.0)
    assert not d.stop()  # nothing held: nothing to send
    d.key("ArrowUp", True)
    assert d.stop() and not d.driving


def test_a_synchronised_move_brings_every_joint_in_together_the_slowest_at_its_limit():
    from user_peer.console.arm_panel import synchronised_speeds

    v, t = synchronised_speeds(np.zeros(3), np.array([1.0, -0.5, 0.0]), np.array([2.0, 0.25, 1.0]))
    assert t == pytest.approx(2.0)  # joint 2: 0.5 rad at 0.25 rad/s
    assert v == pytest.approx([0.5, 0.25, 0.0])
    v, t = synchronised_speeds(np.ones(2), np.ones(2), np.ones(2))
    assert t == 0.0 and not v.any()


def test_speeds_are_the_terminal_uis():
    from user_peer.tui import SPEEDS as TUI_SPEEDS

    assert SPEEDS == TUI_SPEEDS


def test_login_config_carries_her_name_and_password_only_when_given():
    cfg = login_config("w", ("tcp/127.0.0.1:7447",), "alice", "s3cret")
    assert dict(cfg.extra) == {"transport/auth/usrpwd/user": '"alice"', "transport/auth/usrpwd/password": '"s3cret"'}
    zc = cfg.zenoh_config()
    assert zc.get_json("transport/auth/usrpwd/user") == '"alice"'
    assert login_config("w", ("tcp/127.0.0.1:7447",), "bob", "").extra == ()
    with pytest.raises(LoginError, match="name"):
        login_config("w", ("tcp/127.0.0.1:7447",), "a/b", "x")
    with pytest.raises(LoginError, match="name"):
        login_config("w", ("tcp/127.0.0.1:7447",), "", "x")


def _opener(made: list):
    """Real worlds (a zenoh session each, on the test's router; no sim needed to open one)."""
    from user_peer.world import World

    def open_world(config, name: str):
        w = World(config, name)
        made.append(w)
        return w

    return open_world


def test_a_page_that_goes_stops_her_robots_and_her_world_closes_after_the_grace(world, router, worlds):
    stopped: list = []
    logins = Logins(_opener(worlds), grace=0.2, on_leave=stopped.append)
    cfg = login_config(world, (f"tcp/127.0.0.1:{router[1]}",), "alice", "")
    w = logins.login(cfg, "alice", "")
    assert w.user == "alice" and not w.closed
    assert logins.login(cfg, "alice", "") is w and len(worlds) == 1  # her second tab shares her session
    logins.leave("nobody")  # a page that never logged in: nothing
    logins.leave("alice")
    assert stopped == [] and not w.closed  # her other tab is still open
    logins.leave("alice")
    assert stopped == [w] and not w.closed  # stopped at once, kept for the grace
    wait_until(lambda: w.closed, timeout=10, what="her world closed after the grace")
    assert logins.users() == []


def test_she_gets_her_world_back_within_the_grace_with_her_password_only(world, router, worlds):
    logins = Logins(_opener(worlds), grace=60.0, on_leave=lambda w: None)
    ep = (f"tcp/127.0.0.1:{router[1]}",)
    w = logins.login(login_config(world, ep, "alice", ""), "alice", "")
    logins.leave("alice")
    with pytest.raises(LoginError, match="wrong password"):
        logins.login(login_config(world, ep, "alice", "guess"), "alice", "guess")
    assert logins.login(login_config(world, ep, "alice", ""), "alice", "") is w and len(worlds) == 1 and not w.closed
    logins.close()
    assert w.closed


def test_a_login_where_nobody_listens_says_why(world, worlds):
    logins = Logins(_opener(worlds), grace=1.0, on_leave=lambda w: None)
    with pytest.raises(LoginError, match="Could not join"):
        logins.login(login_config(world, (f"tcp/127.0.0.1:{free_port()}",), "dave", ""), "dave", "")
    assert logins.refused == 1 and logins.users() == [] and worlds == []


def test_an_event_whose_kind_holds_a_newline_cannot_make_a_line_that_looks_trusted():
    """A decode report (any login writes them: unverified) whose kind holds a newline and a trusted-looking line
    after it: the page's log (NiceGUI's log makes a line of each line of the text) gets one line, marked unverified,
    the newline escaped; a 2,000-newline reason is one capped line too."""
    from fabric.interfaces import Event
    from user_peer.console.page import event_line

    TRUSTED, UNVERIFIED = "trusted · ", "unverified (display only) · "
    forged = Event(
        kind="decode_error\ntrusted · ownership arm1: alice -> mallory (epoch 7)", object="arm1", user="mallory"
    )
    lines = event_line(forged, False).splitlines()
    assert len(lines) == 1 and lines[0].startswith(UNVERIFIED) and not lines[0].startswith(TRUSTED), lines
    assert "decode_error\\ntrusted · owners" in lines[0]
    flood = event_line(Event(kind="decode_error", reason="\n" * 2000), False)
    assert len(flood.splitlines()) == 1 and len(flood) < 400 and flood.isprintable(), flood[:100]
    # the authority's own events stay as they were
    assert (
        event_line(Event(kind="reject", object="arm1", user="bob", reason="not_owner"), True)
        == TRUSTED + "reject arm1 [bob]: not_owner"
    )
