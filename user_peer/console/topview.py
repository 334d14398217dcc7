"""The console's live view: the world from above as SVG, and the occupancy map as a PNG under it.

A 2D top view rather than a 3D scene: twenty pages on a 2-core machine's software rendering
can afford a few hundred SVG shapes each, not twenty WebGL scenes. What never moves (the scene's
walls and shelves) is drawn into the PNG with the map, once, so the overlay a page redraws holds
only what moves. Pure functions of what a page
holds (poses, scans, paths, a map): no session, no clock, no browser, so they are tested alone.

Coordinates: :class:`Frame` maps world metres (x east, y north) to image pixels (x right, y down).
The map PNG is drawn onto the frame's own pixel grid, so clicks on the image are frame pixels.
"""

from __future__ import annotations

import base64
import functools
import math
import struct
import zlib
from dataclasses import dataclass
from html import escape
from typing import Iterable, Sequence

import numpy as np

from robots.kinds import facts

__all__ = [
    "Frame",
    "RobotMark",
    "svg",
    "robot_svg",
    "scan_path",
    "grid_png",
    "background_png",
    "png_gray",
    "data_url",
    "frame_around",
]

PX_PER_M = 40.0
"""Image pixels per metre: a 10 m scene is a 400-pixel picture (the browser scales it to the panel)."""

COLORS = {"mine": "#e8590c", "other": "#1c7ed6", "free": "#868e96"}


@dataclass(frozen=True, slots=True)
class Frame:
    """The part of the world the view shows, and its scale."""

    xmin: float
    ymin: float
    xmax: float
    ymax: float
    scale: float = PX_PER_M

    @property
    def width(self) -> int:
        return max(1, round((self.xmax - self.xmin) * self.scale))

    @property
    def height(self) -> int:
        return max(1, round((self.ymax - self.ymin) * self.scale))

    def px(self, x: float, y: float) -> tuple[float, float]:
        """World metres to image pixels."""
        return (x - self.xmin) * self.scale, (self.ymax - y) * self.scale

    def world(self, px: float, py: float) -> tuple[float, float]:
        """Image pixels (a click) to world metres."""
        return self.xmin + px / self.scale, self.ymax - py / self.scale


def frame_around(
    points: Iterable[Sequence[float]], *, margin: float = 1.0, minimum: float = 10.0, scale: float = PX_PER_M
) -> Frame:
    """A square frame holding ``points`` (x, y) with ``margin``, at least ``minimum`` metres wide, centred on them."""
    pts = np.asarray([(float(p[0]), float(p[1])) for p in points] or [(0.0, 0.0)])
    lo, hi = pts.min(axis=0) - margin, pts.max(axis=0) + margin
    side = max(minimum, float(np.max(hi - lo)))
    cx, cy = (lo + hi) / 2.0
    return Frame(cx - side / 2, cy - side / 2, cx + side / 2, cy + side / 2, scale)


@dataclass(frozen=True, slots=True)
class RobotMark:
    """One robot as drawn: where it stands, who owns it (``mine``: the page's user), an arm's flange."""

    id: str
    kind: str
    owner: str
    x: float
    y: float
    yaw: float
    mine: bool = False
    selected: bool = False
    flange: tuple[float, float] | None = None
    links: tuple[tuple[float, float], ...] = ()  # an arm's joint origins from its base to its flange (world x, y)


def _f(v: float) -> str:
    return f"{v:.1f}"


def _robot(frame: Frame, r: RobotMark) -> list[str]:
    color = COLORS["mine"] if r.mine else COLORS["other"] if r.owner else COLORS["free"]
    cx, cy = frame.px(r.x, r.y)
    size = 0.3 * frame.scale
    stroke = ' stroke="#212529" stroke-width="3"' if r.selected else ""
    out = []
    if facts(r.kind).base:
        # a triangle pointing where the base faces
        pts = []
        for a, d in ((0.0, size), (2.5, size * 0.8), (-2.5, size * 0.8)):
            pts.append(f"{_f(cx + d * math.cos(r.yaw + a))},{_f(cy - d * math.sin(r.yaw + a))}")
        out.append(f'<polygon points="{" ".join(pts)}" fill="{color}"{stroke}/>')
    else:
        out.append(
            f'<rect x="{_f(cx - size / 2)}" y="{_f(cy - size / 2)}" width="{_f(size)}" height="{_f(size)}" fill="{color}"{stroke}/>'
        )
        if len(r.links) >= 2:  # the arm's links from above: its joints' origins, base to flange
            pts = " ".join(f"{_f(a)},{_f(b)}" for a, b in (frame.px(x, y) for x, y in r.links))
            out.append(
                f'<polyline class="rf-arm-links" points="{pts}" fill="none" stroke="{color}" stroke-width="4" '
                'stroke-linejoin="round"/>'
            )
            out.extend(
                f'<circle cx="{_f(a)}" cy="{_f(b)}" r="2" fill="#212529"/>'
                for a, b in (frame.px(x, y) for x, y in r.links[1:])
            )
        elif r.flange is not None:
            fx, fy = frame.px(*r.flange)
            out.append(
                f'<line x1="{_f(cx)}" y1="{_f(cy)}" x2="{_f(fx)}" y2="{_f(fy)}" stroke="{color}" stroke-width="4"/>'
            )
            out.append(f'<circle cx="{_f(fx)}" cy="{_f(fy)}" r="3" fill="#212529"/>')
    label = f"{r.id} · {r.owner or 'free'}"
    out.append(
        f'<text x="{_f(cx + size * 0.7)}" y="{_f(cy - size * 0.7)}" font-size="12" fill="#212529">{escape(label)}</text>'
    )
    return out


@functools.lru_cache(maxsize=8192)
def robot_svg(frame: Frame, r: RobotMark) -> str:
    """One robot as drawn, kept for the next redraw and the next page: every page of a class draws the same
    robots from the same poses on the same tick (:mod:`user_peer.console.ticker`), and a still robot the same
    way tick after tick, so most of a redraw's robots were drawn before (a frozen mark is its own key)."""
    return "".join(_robot(frame, r))


def svg(
    frame: Frame,
    robots: Sequence[RobotMark],
    *,
    boxes: Sequence[tuple[float, float, float, float, float]] = (),
    scan: np.ndarray | None = None,
    paths: Sequence[np.ndarray] = (),
    target: tuple[float, float] | None = None,
    goal: tuple[float, float, float] | None = None,
    drawn: Sequence[str] = (),
) -> str:
    """The overlay drawn over the map image (an SVG fragment in frame pixels).

    ``boxes``: static scene parts (cx, cy, half x, half y, yaw); ``scan``: N x 2 world points of the selected
    base's LIDAR hits; ``paths``: N x 2 world points each; ``target``: the IK target's (x, y); ``goal``: (x, y, yaw);
    ``drawn``: robots drawn already (:func:`robot_svg`), drawn after ``robots``.
    Names come from the network and are escaped."""
    out: list[str] = []
    for cx, cy, hx, hy, yaw in boxes:
        corners = [(-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy)]
        c, s = math.cos(yaw), math.sin(yaw)
        pts = " ".join(
            f"{_f(p[0])},{_f(p[1])}" for p in (frame.px(cx + c * u - s * v, cy + s * u + c * v) for u, v in corners)
        )
        out.append(f'<polygon points="{pts}" fill="#ced4da" stroke="#adb5bd"/>')
    for path in paths:
        if len(path) >= 2:
            pts = " ".join(f"{_f(a)},{_f(b)}" for a, b in (frame.px(float(x), float(y)) for x, y in path))
            out.append(f'<polyline points="{pts}" fill="none" stroke="#2f9e44" stroke-width="2"/>')
    if scan is not None and len(scan):
        out.append(scan_path(frame, scan))
    if goal is not None:
        gx, gy = frame.px(goal[0], goal[1])
        tip = frame.px(goal[0] + 0.4 * math.cos(goal[2]), goal[1] + 0.4 * math.sin(goal[2]))
        out.append(f'<circle cx="{_f(gx)}" cy="{_f(gy)}" r="6" fill="none" stroke="#2f9e44" stroke-width="3"/>')
        out.append(
            f'<line x1="{_f(gx)}" y1="{_f(gy)}" x2="{_f(tip[0])}" y2="{_f(tip[1])}" stroke="#2f9e44" stroke-width="3"/>'
        )
    if target is not None:
        tx, ty = frame.px(*target)
        out.append(f'<circle cx="{_f(tx)}" cy="{_f(ty)}" r="5" fill="#f59f00" stroke="#212529"/>')
    out.extend(robot_svg(frame, r) for r in robots)
    out.extend(drawn)
    return "".join(out)


def scan_path(frame: Frame, scan: np.ndarray) -> str:
    """A scan's hits as one SVG path of 2-pixel squares on whole pixels, not a shape per ray: one element to
    draw, and hits that fall in the same pixel drawn once (a 240-ray scan: ~3 kB a redraw, less near walls).
    Computed with numpy: five times a second for every page, a loop per ray was a redraw's largest part."""
    pts = np.asarray(scan, dtype=float).reshape(-1, 2)
    px = (
        np.rint(
            np.stack([(pts[:, 0] - frame.xmin) * frame.scale, (frame.ymax - pts[:, 1]) * frame.scale], axis=1)
        ).astype(np.int64)
        - 1
    )
    code = px[:, 0] * 1_000_003 + px[:, 1]  # one number a pixel: numpy's unique is far faster on one axis
    px = px[np.sort(np.unique(code, return_index=True)[1])]  # each pixel once, in the rays' order
    d = "".join(f"M{a} {b}h2v2h-2z" for a, b in px.tolist())
    return f'<path d="{d}" fill="#f03e3e"/>'


def scan_points(
    x: float, y: float, yaw: float, angle_min: float, angle_increment: float, ranges: np.ndarray, range_max: float
) -> np.ndarray:
    """World (x, y) of a scan's hits (rays that reached ``range_max`` hit nothing and are left out)."""
    r = np.asarray(ranges, dtype=float)
    a = yaw + angle_min + angle_increment * np.arange(len(r))
    hit = r < range_max - 1e-3
    return np.stack([x + r[hit] * np.cos(a[hit]), y + r[hit] * np.sin(a[hit])], axis=1)


UNKNOWN, BOX = 230, 200
"""Grey levels of the background: unknown or outside the map, and the scene's static boxes."""


def grid_png(cells: np.ndarray, resolution: float, origin: Sequence[float], frame: Frame) -> bytes:
    """The occupancy grid resampled onto the frame's pixels (nearest cell) as a grey PNG: free white,
    occupied black, unknown and outside light grey. The grid's own rotation (origin theta) is honoured."""
    return png_gray(grid_pixels(cells, resolution, origin, frame))


def background_png(
    frame: Frame,
    boxes: Sequence[tuple[float, float, float, float, float]] = (),
    grid: tuple[np.ndarray, float, Sequence[float]] | None = None,
) -> bytes:
    """The view's still picture: the map (``grid``: cells, resolution, origin; unknown grey without one) with the
    scene's static boxes (cx, cy, half x, half y, yaw) in :data:`BOX` grey over it, except where the map saw
    something darker (an occupied cell stays black). Drawn once per map, not with every redraw of the overlay;
    without a map, once per frame for the whole console (:func:`_scene_png`): every page of a class starts on the
    same picture, and drawing it took a sixth of a page's build."""
    if grid is None:
        return _scene_png(frame, tuple(tuple(float(v) for v in b) for b in boxes))
    return _drawn_png(frame, boxes, grid)


@functools.lru_cache(maxsize=16)
def _scene_png(frame: Frame, boxes: tuple[tuple[float, ...], ...]) -> bytes:
    """The scene's walls on unknown grey, for ``frame``: the same bytes for every page that shows it."""
    return _drawn_png(frame, boxes, None)


def _drawn_png(
    frame: Frame, boxes: Sequence[Sequence[float]], grid: tuple[np.ndarray, float, Sequence[float]] | None
) -> bytes:
    img = grid_pixels(*grid, frame) if grid is not None else np.full((frame.height, frame.width), UNKNOWN, np.uint8)
    if boxes:
        X, Y = _pixel_centres(frame)
        for cx, cy, hx, hy, yaw in boxes:
            c, s = math.cos(yaw), math.sin(yaw)
            u, v = c * (X - cx) + s * (Y - cy), -s * (X - cx) + c * (Y - cy)
            img[(np.abs(u) <= hx) & (np.abs(v) <= hy) & (img > BOX)] = BOX
    return png_gray(img)


def _pixel_centres(frame: Frame) -> tuple[np.ndarray, np.ndarray]:
    """World (x, y) of every pixel's centre, as two H x W arrays."""
    px = (np.arange(frame.width) + 0.5) / frame.scale + frame.xmin
    py = frame.ymax - (np.arange(frame.height) + 0.5) / frame.scale
    return np.meshgrid(px, py)


def grid_pixels(cells: np.ndarray, resolution: float, origin: Sequence[float], frame: Frame) -> np.ndarray:
    """:func:`grid_png`'s picture as an H x W uint8 array."""
    h, w = frame.height, frame.width
    X, Y = _pixel_centres(frame)
    ox, oy, th = (float(v) for v in origin)
    c, s = math.cos(th), math.sin(th)
    u, v = c * (X - ox) + s * (Y - oy), -s * (X - ox) + c * (Y - oy)
    col, row = np.floor(u / resolution).astype(int), np.floor(v / resolution).astype(int)
    inside = (row >= 0) & (row < cells.shape[0]) & (col >= 0) & (col < cells.shape[1])
    img = np.full((h, w), UNKNOWN, dtype=np.uint8)
    val = cells[np.clip(row, 0, cells.shape[0] - 1), np.clip(col, 0, cells.shape[1] - 1)]
    known = inside & (val != 255)
    img[known] = (255 - (val[known].astype(np.int32) * 255 // 100)).astype(np.uint8)
    return img


def png_gray(img: np.ndarray) -> bytes:
    """An 8-bit greyscale PNG of ``img`` (H x W uint8), with the standard library only."""
    img = np.ascontiguousarray(img, dtype=np.uint8)
    h, w = img.shape
    raw = b"".join(b"\x00" + img[i].tobytes() for i in range(h))

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0))
        + chunk(b"IDAT", zlib.compress(raw, 6))
        + chunk(b"IEND", b"")
    )


def data_url(png: bytes) -> str:
    """A PNG as a data: URL (the page asks no host for it)."""
    return "data:image/png;base64," + base64.b64encode(png).decode()
