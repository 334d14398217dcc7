"""Saving and loading maps: PGM + YAML as ROS map_server does, or one NPZ file.

PGM + YAML follows map_server's conventions so maps move both ways between
robofabric and ROS tools: the image's top row is the map's highest y; pixels
are written 254 free, 0 occupied, 205 unknown (``mode: trinary``) for binary
maps, and as a grey scale (``mode: scale``) otherwise; on load a pixel's
occupancy is ``(255 - p) / 255`` (inverted if ``negate: 1``) compared with
``occupied_thresh`` / ``free_thresh``. Only the YAML keys map_server writes are
read, so a tiny parser suffices (no YAML dependency).
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from fabric.interfaces import OccupancyGrid

from .errors import NavigationError
from .grid import UNKNOWN, check_grid, make_grid

OCCUPIED_THRESH = 0.65
FREE_THRESH = 0.196


def _is_binary(cells: np.ndarray) -> bool:
    return bool(np.isin(cells, (0, 100, UNKNOWN)).all())


def save_pgm_yaml(grid: OccupancyGrid, yaml_path: str | Path) -> Path:
    """Write ``NAME.yaml`` and ``NAME.pgm`` beside it; returns the YAML path."""
    check_grid(grid)
    yaml_path = Path(yaml_path)
    if yaml_path.suffix not in (".yaml", ".yml"):
        yaml_path = yaml_path.with_suffix(".yaml")
    pgm_path = yaml_path.with_suffix(".pgm")
    cells = grid.cells
    binary = _is_binary(cells)
    known = cells != UNKNOWN
    px = np.full(cells.shape, 205, dtype=np.uint8)
    if binary:
        px[known & (cells >= 50)] = 0
        px[known & (cells < 50)] = 254
    else:
        occ = cells[known].astype(np.float64) / 100.0
        px[known] = np.rint(255.0 * (1.0 - occ)).astype(np.uint8)
    px = np.flipud(px)
    h, w = px.shape
    with open(pgm_path, "wb") as f:
        f.write(f"P5\n# robofabric map\n{w} {h}\n255\n".encode("ascii"))
        f.write(np.ascontiguousarray(px).tobytes())
    ox, oy, oyaw = (float(v) for v in grid.origin)
    yaml_path.write_text(
        f"image: {pgm_path.name}\n"
        f"mode: {'trinary' if binary else 'scale'}\n"
        f"resolution: {grid.resolution!r}\n"
        f"origin: [{ox!r}, {oy!r}, {oyaw!r}]\n"
        "negate: 0\n"
        f"occupied_thresh: {OCCUPIED_THRESH}\n"
        f"free_thresh: {FREE_THRESH}\n"
    )
    return yaml_path


def _parse_yaml(text: str) -> dict[str, str]:
    out: dict[str, str] = {}
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        m = re.match(r"^([A-Za-z_]+)\s*:\s*(.*)$", line)
        if m is None:
            raise NavigationError(f"map YAML line not understood: {line!r}")
        out[m.group(1)] = m.group(2).strip().strip("'\"")
    return out


def _read_pgm(path: Path) -> np.ndarray:
    data = path.read_bytes()
    tokens: list[bytes] = []
    pos = 0
    while len(tokens) < 4:  # magic, width, height, maxval (comments allowed in between)
        while pos < len(data) and data[pos : pos + 1].isspace():
            pos += 1
        if data[pos : pos + 1] == b"#":
            pos = data.index(b"\n", pos) + 1
            continue
        start = pos
        while pos < len(data) and not data[pos : pos + 1].isspace():
            pos += 1
        if start == pos:
            raise NavigationError(f"{path}: truncated PGM header")
        tokens.append(data[start:pos])
    magic = tokens[0]
    try:
        w, h, maxval = (int(t) for t in tokens[1:4])
    except ValueError:
        raise NavigationError(f"{path}: bad PGM header {tokens!r}") from None
    if magic == b"P5":
        if maxval > 255:
            raise NavigationError(f"{path}: 16-bit PGM is not supported")
        raw = data[pos + 1 : pos + 1 + w * h]
        if len(raw) != w * h:
            raise NavigationError(f"{path}: PGM has {len(raw)} pixel bytes, expected {w * h}")
        px = np.frombuffer(raw, dtype=np.uint8).reshape(h, w)
    elif magic == b"P2":
        vals = np.array(data[pos:].split()[: w * h], dtype=np.int64)
        if vals.size != w * h:
            raise NavigationError(f"{path}: PGM has {vals.size} pixels, expected {w * h}")
        px = vals.reshape(h, w)
    else:
        raise NavigationError(f"{path}: not a PGM file (magic {magic!r})")
    return px.astype(np.float64) * (255.0 / maxval)


def load_pgm_yaml(yaml_path: str | Path) -> OccupancyGrid:
    yaml_path = Path(yaml_path)
    if not yaml_path.is_file():
        raise NavigationError(f"no map file {yaml_path}")
    meta = _parse_yaml(yaml_path.read_text())
    for key in ("image", "resolution", "origin"):
        if key not in meta:
            raise NavigationError(f"{yaml_path}: missing '{key}'")
    try:
        resolution = float(meta["resolution"])
        origin = [float(v) for v in meta["origin"].strip("[]").split(",")]
        negate = int(meta.get("negate", "0"))
        occ_t = float(meta.get("occupied_thresh", OCCUPIED_THRESH))
        free_t = float(meta.get("free_thresh", FREE_THRESH))
    except ValueError as exc:
        raise NavigationError(f"{yaml_path}: {exc}") from None
    if len(origin) != 3 or not all(math.isfinite(v) for v in origin) or not (resolution > 0):
        raise NavigationError(f"{yaml_path}: origin must be [x, y, yaw] and resolution positive")
    if abs(origin[2]) > 1e-9:
        raise NavigationError(f"{yaml_path}: rotated map origins are not supported")
    mode = meta.get("mode", "trinary")
    image = yaml_path.parent / meta["image"]
    if not image.is_file():
        raise NavigationError(f"{yaml_path}: image {image.name} not found beside it")
    px = np.flipud(_read_pgm(image))
    occ = px / 255.0 if negate else (255.0 - px) / 255.0
    cells = np.full(px.shape, UNKNOWN, dtype=np.uint8)
    cells[occ > occ_t] = 100
    cells[occ < free_t] = 0
    if mode == "scale":
        mid = (occ >= free_t) & (occ <= occ_t)
        cells[mid] = np.rint(99.0 * (occ[mid] - free_t) / (occ_t - free_t)).astype(np.uint8)
        cells[mid & (np.abs(px - 205.0) < 0.5)] = UNKNOWN
    elif mode != "trinary":
        raise NavigationError(f"{yaml_path}: map mode {mode!r} is not supported (trinary or scale)")
    return make_grid(cells, resolution, (origin[0], origin[1]))


def save_npz(grid: OccupancyGrid, path: str | Path) -> Path:
    check_grid(grid)
    path = Path(path)
    if path.suffix != ".npz":
        path = path.with_suffix(".npz")
    np.savez_compressed(path, cells=grid.cells, resolution=np.float64(grid.resolution), origin=np.asarray(grid.origin))
    return path


def load_npz(path: str | Path) -> OccupancyGrid:
    path = Path(path)
    if not path.is_file():
        raise NavigationError(f"no map file {path}")
    try:
        with np.load(path, allow_pickle=False) as z:
            cells, res, origin = z["cells"], float(z["resolution"]), z["origin"]
    except (KeyError, ValueError, OSError) as exc:
        raise NavigationError(f"{path}: not a robofabric map ({exc})") from None
    try:
        grid = OccupancyGrid(res, np.asarray(origin, dtype=np.float64), np.asarray(cells, dtype=np.uint8))
        grid.check()
    except (ValueError, TypeError) as exc:
        raise NavigationError(f"{path}: {exc}") from None
    check_grid(grid)
    return grid


def save_map(grid: OccupancyGrid, path: str | Path) -> Path:
    """Save by extension: ``.npz`` as NPZ, anything else as PGM + YAML."""
    return save_npz(grid, path) if str(path).endswith(".npz") else save_pgm_yaml(grid, path)


def load_map(path: str | Path) -> OccupancyGrid:
    return load_npz(path) if str(path).endswith(".npz") else load_pgm_yaml(path)
