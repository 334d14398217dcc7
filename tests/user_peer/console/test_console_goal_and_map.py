"""The base panel's typed goal (:mod:`user_peer.console.goal`) and the map's zoom, scale bar and legend
(:mod:`user_peer.console.mapframe`): pure functions of the text and the frame."""

from __future__ import annotations

import re

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from user_peer.console.goal import read_metres, typed_goal
from user_peer.console.mapframe import LEGEND, ZOOMS, bar_metres, legend_html, scale_bar_svg, zoomed
from user_peer.console.topview import COLORS, Frame

WHOLE = Frame(-5.2, -5.0, 5.2, 5.4)


@pytest.mark.parametrize(
    "text, metres",
    [("-2.5", -2.5), (" -2,5 ", -2.5), ("3 m", 3.0), ("0.5metres", 0.5), ("\u22121", -1.0), ("1e-1", 0.1)],
)
def test_a_typed_number_reads_as_a_student_means_it(text, metres):
    assert read_metres(text) == pytest.approx(metres)


@pytest.mark.parametrize("text", ["", "abc", "nan", "inf", "-", "1.2.3", "2 km"])
def test_what_is_no_finite_number_reads_as_none(text):
    assert read_metres(text) is None


def test_a_goal_on_the_map_is_taken():
    assert typed_goal("-2.5", "0,5", WHOLE).xy == (-2.5, 0.5)
    assert typed_goal("-2.5", "0,5", WHOLE).errors == ()


def test_each_bad_field_says_in_plain_words_what_to_type_and_the_good_one_is_not_blamed():
    g = typed_goal("", "abc", WHOLE)
    assert g.xy is None and [f for f, _ in g.errors] == ["x", "y"]
    assert dict(g.errors)["x"].startswith("Goal x is empty: type a number of metres, e.g.")
    assert dict(g.errors)["y"].startswith("Goal y 'abc' is not a number: type metres with a point")
    off = typed_goal("1", "12", WHOLE)
    assert [f for f, _ in off.errors] == ["y"]
    assert off.message() == "Goal y 12.00 m is off the map: type a number from -5.00 to 5.40"
    assert "\n" not in typed_goal("a\nb", "", WHOLE).message()


@given(st.floats(-100, 100), st.floats(-100, 100))
@settings(deadline=None)
def test_a_typed_goal_is_taken_exactly_when_it_is_on_the_map(x, y):
    g = typed_goal(repr(x), repr(y), WHOLE)
    on = WHOLE.xmin <= x <= WHOLE.xmax and WHOLE.ymin <= y <= WHOLE.ymax
    assert (g.xy == (x, y)) if on else (g.xy is None and g.errors)


@given(st.sampled_from(ZOOMS), st.floats(-20, 20), st.floats(-20, 20))
@settings(deadline=None)
def test_a_zoomed_frame_is_inside_the_whole_the_same_picture_size_at_level_times_the_scale(level, cx, cy):
    f = zoomed(WHOLE, level, (cx, cy))
    assert (f.width, f.height) == (WHOLE.width, WHOLE.height)  # clicks and the picture keep their pixels
    assert f.scale == pytest.approx(WHOLE.scale * level)
    assert (
        f.xmin >= WHOLE.xmin - 1e-9
        and f.xmax <= WHOLE.xmax + 1e-9
        and f.ymin >= WHOLE.ymin - 1e-9
        and f.ymax <= WHOLE.ymax + 1e-9
    )
    if level > 1 and WHOLE.xmin + 5.2 / level <= cx <= WHOLE.xmax - 5.2 / level:
        assert (f.xmin + f.xmax) / 2 == pytest.approx(cx)  # centred on it when the frame need not move to stay inside
    x, y = f.world(*f.px(cx, cy))
    assert (x, y) == (pytest.approx(cx), pytest.approx(cy))


def test_the_scale_bar_is_a_round_length_within_a_quarter_of_the_width_drawn_at_the_frames_scale():
    assert bar_metres(WHOLE) == 2.0  # 10.4 m wide: a quarter is 2.6 m
    assert bar_metres(zoomed(WHOLE, 4, (0, 0))) == 0.5  # 2.6 m wide
    assert bar_metres(zoomed(WHOLE, 8, (0, 0))) == 0.2
    for level in ZOOMS:
        f = zoomed(WHOLE, level, (0, 0))
        svg = scale_bar_svg(f)
        width = float(re.search(r'class="rf-scale-bar-line" x="[\d.]+" y="[\d.]+" width="([\d.]+)"', svg).group(1))
        assert width == pytest.approx(bar_metres(f) * f.scale, abs=0.05)
        assert 0.1 * f.width < width <= 0.25 * f.width + 0.05
    assert ">2 m</text>" in scale_bar_svg(WHOLE) and ">50 cm</text>" in scale_bar_svg(zoomed(WHOLE, 4, (0, 0)))


def test_the_legend_names_every_colour_the_map_uses():
    html = legend_html()
    for color in COLORS.values():
        assert color in html
    for words in (
        "your robot",
        "someone else's",
        "free robot",
        "IK target",
        "goal",
        "path",
        "LIDAR hits",
        "map: occupied",
    ):
        assert f"{words}</li>" in html.replace("&#x27;", "'")
    assert html.count("<li ") == len(LEGEND) and 'aria-label="Map legend"' in html
