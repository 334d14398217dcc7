"""The top-down map's zoom, scale bar and legend: what a student needs to read distances and colours off it.

Zoom is a smaller frame at a larger scale, the picture keeping its pixel size, so a click still lands on a
frame pixel and the server draws the zoomed map and overlay as sharply as the whole one (a CSS zoom would
blur the map's cells and move the clicks). The scale bar is drawn in the overlay's pixels, so it scales with
the picture on any screen. Pure functions of a frame: tested alone.
"""

from __future__ import annotations

from html import escape

from user_peer.console.topview import COLORS, Frame

__all__ = ["ZOOMS", "zoomed", "bar_metres", "scale_bar_svg", "LEGEND", "legend_html"]

ZOOMS = (1, 2, 4, 8)
"""The zoom levels: the whole map, then half, a quarter, an eighth of its width (8: a 10 m map shows 1.25 m)."""


def zoomed(whole: Frame, level: float, centre: tuple[float, float]) -> Frame:
    """The part of ``whole`` ``level`` times smaller around ``centre``, kept inside ``whole`` (a base near a wall
    zooms to the corner, not to the outside), at ``level`` times the scale: the same picture size in pixels."""
    if level <= 1:
        return whole
    wx, wy = (whole.xmax - whole.xmin) / level, (whole.ymax - whole.ymin) / level
    cx = min(max(centre[0], whole.xmin + wx / 2), whole.xmax - wx / 2)
    cy = min(max(centre[1], whole.ymin + wy / 2), whole.ymax - wy / 2)
    return Frame(cx - wx / 2, cy - wy / 2, cx + wx / 2, cy + wy / 2, whole.scale * level)


def bar_metres(frame: Frame) -> float:
    """The scale bar's length: the longest of 1, 2 or 5 times a power of ten within a quarter of the frame's width."""
    quarter = (frame.xmax - frame.xmin) / 4
    best = 0.01
    for exp in range(-2, 4):
        for m in (1, 2, 5):
            if m * 10.0**exp <= quarter + 1e-9:
                best = m * 10.0**exp
    return best


def _words(metres: float) -> str:
    return f"{metres:g} m" if metres >= 1 else f"{metres * 100:g} cm"


def scale_bar_svg(frame: Frame) -> str:
    """The scale bar in the overlay's bottom-left corner: a black bar of :func:`bar_metres` on a white ground,
    with its length in words (``data-metres`` for a test or a script)."""
    m = bar_metres(frame)
    length = m * frame.scale
    x0, y0 = 10.0, frame.height - 12.0
    return (
        f'<g class="rf-scale-bar" data-metres="{m:g}">'
        f'<rect x="{x0 - 4:.1f}" y="{y0 - 18:.1f}" width="{length + 8:.1f}" height="26" fill="#ffffff" fill-opacity="0.85"/>'
        f'<rect class="rf-scale-bar-line" x="{x0:.1f}" y="{y0:.1f}" width="{length:.1f}" height="4" fill="#212529"/>'
        f'<text x="{x0:.1f}" y="{y0 - 5:.1f}" font-size="12" fill="#212529">{_words(m)}</text></g>'
    )


LEGEND: tuple[tuple[str, str], ...] = (
    (f'<polygon points="2,12 14,7 2,2" fill="{COLORS["mine"]}"/>', "your robot"),
    (f'<polygon points="2,12 14,7 2,2" fill="{COLORS["other"]}"/>', "someone else's"),
    (f'<polygon points="2,12 14,7 2,2" fill="{COLORS["free"]}"/>', "free robot"),
    ('<polygon points="2,12 14,7 2,2" fill="#ffffff" stroke="#212529" stroke-width="2"/>', "selected"),
    ('<ellipse cx="7" cy="7" rx="5" ry="5" fill="#f59f00" stroke="#212529"/>', "IK target"),
    ('<ellipse cx="7" cy="7" rx="5" ry="5" fill="none" stroke="#2f9e44" stroke-width="2.5"/>', "goal"),
    ('<line x1="1" y1="7" x2="13" y2="7" stroke="#2f9e44" stroke-width="2"/>', "path"),
    (
        '<rect x="3" y="3" width="3" height="3" fill="#f03e3e"/><rect x="8" y="8" width="3" height="3" fill="#f03e3e"/>',
        "LIDAR hits",
    ),
    ('<rect x="1" y="3" width="12" height="8" fill="#ced4da" stroke="#adb5bd"/>', "walls, shelves"),
    ('<rect x="1" y="3" width="12" height="8" fill="#000000"/>', "map: occupied"),
    ('<rect x="1" y="3" width="12" height="8" fill="#ffffff" stroke="#868e96"/>', "map: free"),
    ('<rect x="1" y="3" width="12" height="8" fill="#e6e6e6" stroke="#868e96"/>', "map: unknown"),
)
"""What each mark of the map means (the colours of :mod:`.topview`): a swatch and its words. Dots are ellipses, not
circles: a script (or a test) that finds the map's target or goal by its circle finds the map's, not the legend's."""


def legend_html() -> str:
    """The legend as a list (a screen reader reads its words; the swatches are decoration)."""
    items = "".join(
        f'<li style="display:inline-flex;align-items:center;gap:0.25rem;margin-right:0.75rem">'
        f'<svg width="14" height="14" aria-hidden="true" focusable="false">{swatch}</svg>{escape(words)}</li>'
        for swatch, words in LEGEND
    )
    return f'<ul class="rf-legend" aria-label="Map legend" style="list-style:none;padding:0;margin:0;font-size:0.8rem">{items}</ul>'
