"""Maps saved and loaded as PGM + YAML (ROS map_server conventions) and NPZ."""

from __future__ import annotations

import numpy as np
import pytest

from compute_peer.navigation import (
    NavigationError,
    load_map,
    load_npz,
    load_pgm_yaml,
    save_map,
    save_npz,
    save_pgm_yaml,
)
from compute_peer.navigation.grid import UNKNOWN, make_grid


def binary_grid():
    rng = np.random.default_rng(3)
    cells = rng.choice(np.array([0, 100, UNKNOWN], dtype=np.uint8), size=(37, 53), p=[0.6, 0.3, 0.1])
    return make_grid(cells, 0.05, (-1.25, 2.5))


def test_pgm_yaml_round_trip_of_a_binary_map(tmp_path):
    grid = binary_grid()
    yaml_path = save_pgm_yaml(grid, tmp_path / "office.yaml")
    text = yaml_path.read_text()
    assert "image: office.pgm" in text and "mode: trinary" in text and "origin: [-1.25, 2.5, 0.0]" in text
    pgm = (tmp_path / "office.pgm").read_bytes()
    assert pgm.startswith(b"P5")
    # the image's top row is the map's highest y, pixels 254 free / 0 occupied / 205 unknown
    px = np.frombuffer(pgm[-grid.cells.size :], dtype=np.uint8).reshape(grid.cells.shape)
    expect = np.select([grid.cells == 0, grid.cells == 100], [254, 0], 205)
    assert np.array_equal(px, np.flipud(expect))
    back = load_pgm_yaml(yaml_path)
    assert back.resolution == grid.resolution
    assert np.array_equal(back.origin, grid.origin)
    assert np.array_equal(back.cells, grid.cells)


def test_npz_round_trip_keeps_probabilities(tmp_path):
    rng = np.random.default_rng(4)
    cells = rng.integers(0, 101, size=(20, 30)).astype(np.uint8)
    cells[0, :5] = UNKNOWN
    grid = make_grid(cells, 0.1, (3.0, -4.0))
    back = load_map(save_map(grid, tmp_path / "p.npz"))
    assert (
        np.array_equal(back.cells, grid.cells) and back.resolution == 0.1 and np.array_equal(back.origin, grid.origin)
    )


def test_scale_mode_keeps_occupied_free_and_unknown(tmp_path):
    cells = np.array([[0, 10, 50, 90, 100, UNKNOWN]], dtype=np.uint8)
    back = load_map(save_map(make_grid(cells, 0.1), tmp_path / "scaled"))
    assert "mode: scale" in (tmp_path / "scaled.yaml").read_text()
    assert back.cells[0, 0] == 0 and back.cells[0, 1] == 0
    assert back.cells[0, 3] == 100 and back.cells[0, 4] == 100
    assert back.cells[0, 5] == UNKNOWN
    assert 0 < back.cells[0, 2] < 100


def test_reads_a_ros_style_ascii_map_with_comments(tmp_path):
    (tmp_path / "m.pgm").write_text("P2\n# made by hand\n3 2\n255\n254 0 205\n0 254 254\n")
    (tmp_path / "m.yaml").write_text(
        "# map_server file\nimage: m.pgm\nresolution: 0.5\norigin: [1.0, 2.0, 0.0]\nnegate: 0\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )
    grid = load_pgm_yaml(tmp_path / "m.yaml")
    # bottom image row is y row 0
    assert grid.cells.tolist() == [[100, 0, 0], [0, 100, UNKNOWN]]
    assert grid.resolution == 0.5 and grid.origin.tolist() == [1.0, 2.0, 0.0]


@pytest.mark.parametrize(
    "yaml_text, match",
    [
        ("image: m.pgm\nresolution: 0.5\n", "origin"),
        ("image: m.pgm\nresolution: 0.5\norigin: [0, 0, 0.7]\n", "rotated"),
        ("image: m.pgm\nresolution: abc\norigin: [0, 0, 0]\n", "abc"),
        ("image: missing.pgm\nresolution: 0.5\norigin: [0, 0, 0]\n", "missing.pgm not found"),
    ],
)
def test_bad_map_files_are_refused(tmp_path, yaml_text, match):
    (tmp_path / "m.pgm").write_bytes(b"P5\n2 2\n255\n\x00\x00\x00\x00")
    (tmp_path / "m.yaml").write_text(yaml_text)
    with pytest.raises(NavigationError, match=match):
        load_pgm_yaml(tmp_path / "m.yaml")


def test_bad_pgm_and_npz_are_refused(tmp_path):
    (tmp_path / "m.pgm").write_bytes(b"P5\n4 4\n255\n\x00\x00")
    (tmp_path / "m.yaml").write_text("image: m.pgm\nresolution: 0.5\norigin: [0, 0, 0]\n")
    with pytest.raises(NavigationError, match="pixel bytes"):
        load_pgm_yaml(tmp_path / "m.yaml")
    np.savez(tmp_path / "x.npz", something=np.zeros(3))
    with pytest.raises(NavigationError, match="not a robofabric map"):
        load_npz(tmp_path / "x.npz")
    with pytest.raises(NavigationError, match="no map file"):
        load_map(tmp_path / "absent.npz")
    save_npz(make_grid(np.zeros((2, 2), np.uint8), 0.1), tmp_path / "ok")
    assert (tmp_path / "ok.npz").is_file()
