"""print_table (fabric/cli_common.py): every table fits the terminal or prints its rows as blocks; no column
is dropped and no word cut (``list`` at 80 columns keeps its msgs and kB/s columns and its peer ids whole). The live commands are checked at 60, 80 and 120 columns in test_introspect_cli.py."""

from __future__ import annotations

import re

import pytest

from fabric.cli_common import column_widths, print_table

COLUMNS = ("key", "type", "publishers", "subscribers", "rate Hz", "msgs", "kB/s")
ROWS = [
    (
        "rf/demo/robot/arm1/joints",
        "JointState",
        "sim-vm-6954b3",
        "sim-vm-6954b3, viewer-vm-0a1b2c",
        "98.6",
        "99",
        "21.3",
    ),
    ("rf/demo/robot/base1/scan", "Scan", "sim-vm-6954b3", "-", "20.2", "20", "11.5"),
]
WORDS = {"JointState", "Scan", "sim-vm-6954b3", "viewer-vm-0a1b2c", "98.6", "99", "21.3", "20.2", "11.5"}


@pytest.mark.parametrize("width", [60, 80, 120])
def test_a_table_fits_and_keeps_every_column_and_word(width, monkeypatch, capsys):
    monkeypatch.setenv("COLUMNS", str(width))
    print_table("rf/demo/**: 2 key(s)", COLUMNS, ROWS, numeric=("rate Hz", "msgs", "kB/s"))
    out = capsys.readouterr().out
    assert max(len(line) for line in out.splitlines()) <= width, out
    words = set(re.split(r"[\s│┃,]+", out))
    assert WORDS <= words, (WORDS - words, out)
    for head in ("type", "publishers", "subscribers", "msgs", "kB/s"):
        assert head in words or f"{head}:" in words, (head, out)
    flat = "".join(out.split())
    assert "rf/demo/robot/arm1/joints" in flat or "rf/demo/robot/arm1/joints" in _column0(out), out


def _column0(text: str) -> str:
    lines = [line for line in text.splitlines() if line.strip()]
    if any("│" in line for line in lines):
        return "".join(c[1].strip() for line in lines if len(c := line.split("│")) > 2)
    rule = next(i for i, line in enumerate(lines) if set(line.strip()) == {"─"})
    header = lines[rule - 1]
    width = len(header) - len(header[len(header.split()[0]) :].lstrip()) - 3
    return "".join(line[:width].strip() for line in lines[rule + 1 :])


def test_widths_never_go_below_a_word_nor_above_the_room():
    for width in range(40, 140, 7):
        for boxed in (True, False):
            widths = column_widths(COLUMNS, ROWS, width, boxed=boxed, whole=(4, 5, 6))
            if widths is None:
                continue
            spent = sum(widths) + (3 * len(COLUMNS) + 1 if boxed else 3 * (len(COLUMNS) - 1))
            assert spent <= width, (width, boxed, widths)
            assert (
                widths[2] >= len("sim-vm-6954b3")
                and widths[3] >= len("viewer-vm-0a1b2c")
                and widths[1] >= len("JointState")
            )
    assert column_widths(COLUMNS, ROWS, 40) is None  # too narrow for the columns side by side: blocks
    assert column_widths(COLUMNS, ROWS, 200) == [max(len(c), *(len(r[i]) for r in ROWS)) for i, c in enumerate(COLUMNS)]


def test_a_cell_from_the_network_is_one_escaped_line(monkeypatch, capsys):
    """A peer id with a newline and an escape sequence (a token's id is any login's text): its row stays one row,
    the terminal gets no escape sequence, the text is readable."""
    monkeypatch.setenv("COLUMNS", "120")
    print_table("world w: 2 peer(s)", ("kind", "id"), [("user", "x\x1b[2J\nsim  real-sim"), ("sim", "sim-1")])
    out = capsys.readouterr().out
    assert "\x1b" not in out and "x\\x1b[2J\\nsim  real-sim" in out, out
    assert not [line for line in out.splitlines() if line.lstrip("│ ").startswith("sim  real-sim")], out
