"""``robofabric bench soak`` refuses bad options with what it expects, and ``--recheck`` judges a kept history:
each violation with its excerpt, the three summary lines, exit 1 when there is a violation."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from robofabric.soak.history import Fault, Mark, OwnRec, ProcSample, Writer

pytestmark = pytest.mark.slow  # a robofabric process each

ROOT = Path(__file__).resolve().parents[3]


def soak(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "robofabric.cli", "bench", "soak", *args],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=ROOT,
    )


def _history(folder: Path, owners: tuple[str, str]) -> Path:
    with Writer(folder / "wire.jsonl") as w:
        w.write(OwnRec(1.0, "arm0", owners[0], 3, (), "still", "sim-a", 1))
        w.write(OwnRec(2.0, "arm0", owners[1], 3, (), "still", "sim-a", 1))
    with Writer(folder / "soak.jsonl") as w:
        w.write(Mark(0.5, "start"))
        w.write(Fault(1.5, "pause", "sim-b", 2.5, "1.0 s"))
        w.write(ProcSample(1.6, "sim-a", 42, 95.0, 18, 15, 300))
        w.write(Mark(181.5, "end", "1 faults"))
    return folder


@pytest.mark.parametrize(
    "args",
    [
        ["--plant", "nope"],
        ["--faults", "pause,flood"],
        ["--victims", "router"],
        ["--victims", "sim=0"],
        ["--students", "1"],
    ],
)
def test_bad_options_are_refused_with_what_is_expected(args):
    res = soak(*args)
    assert res.returncode == 2, res.stdout + res.stderr
    assert "expected" in res.stderr or "at least" in res.stderr, res.stderr


def test_recheck_prints_the_violation_its_excerpt_and_the_summary(tmp_path):
    res = soak("--recheck", str(_history(tmp_path, ("ann", "bob"))))
    assert res.returncode == 1, res.stdout + res.stderr
    lines = res.stdout.splitlines()
    assert lines[0] == "VIOLATION owners: arm0 has two owners at epoch 3: ann and bob"
    assert lines[1].strip().startswith("t=1.000 record arm0: owner=ann epoch=3")
    assert lines[-3:] == ["faults: 1", "fault kinds: 1 (pause 1)", "violations: 1 (owners 1)"]


def test_recheck_writes_the_figures_with_the_violations_it_found_now(tmp_path):
    """--recheck --out: the document a run writes (what the plot draws), its violations today's checker's."""
    out = tmp_path / "again.json"
    res = soak("--recheck", str(_history(tmp_path, ("ann", "bob"))), "--out", str(out))
    assert res.returncode == 1, res.stdout + res.stderr
    doc = json.loads(out.read_text())
    assert doc["violations"] == [
        "VIOLATION owners: arm0 has two owners at epoch 3: ann and bob\n" + "\n".join(res.stdout.splitlines()[1:3])
    ], doc["violations"]
    assert doc["faults"] == {"pause": 1} and doc["minutes"] == 3.0
    assert doc["memory_mb"] == {"sim-a": [[0.0, 95.0]]}
    assert doc["summary"][-1] == "violations: 1 (owners 1)"


def test_recheck_of_a_clean_history_exits_0(tmp_path):
    res = soak("--recheck", str(_history(tmp_path, ("ann", "ann"))))
    assert res.returncode == 0, res.stdout + res.stderr
    assert res.stdout.splitlines()[-1] == "violations: 0"


def test_recheck_of_a_folder_without_a_history_says_what_it_expects(tmp_path):
    res = soak("--recheck", str(tmp_path))
    assert res.returncode == 2 and "wire.jsonl and soak.jsonl" in res.stderr, res.stderr
