"""The hang watch: a test pytest-timeout cannot end is ended, its stacks said and its processes killed, and the
run goes on (robofabric/hang_watch.py)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from robofabric.hang_watch import HUNG_EXIT, children_of, descendants


def _stat(root: Path, pid: int, name: str, ppid: int) -> None:
    (root / str(pid)).mkdir()
    (root / str(pid) / "stat").write_text(f"{pid} ({name}) S {ppid} {pid} {pid} 0 -1 4194560\n")


def test_children_are_read_past_a_command_name_with_spaces_and_parentheses(tmp_path: Path) -> None:
    _stat(tmp_path, 10, "pytest", 1)
    _stat(tmp_path, 11, "python -m robofabric (sim) x", 10)
    _stat(tmp_path, 12, "zenohd", 11)
    (tmp_path / "self").mkdir()  # not a pid
    (tmp_path / "13").mkdir()  # a process gone while it was read: no stat
    assert children_of(tmp_path) == {1: [10], 10: [11], 11: [12]}


def test_descendants_are_every_generation_once_and_never_the_process_itself() -> None:
    tree = {1: [10, 20], 10: [11, 12], 11: [13], 20: [21], 13: [1]}  # a loop back to the root is no descendant
    assert descendants(1, tree) == [10, 20, 11, 12, 21, 13]
    assert descendants(10, tree) == [11, 12, 13, 1, 20, 21]
    assert descendants(99, tree) == []


HUNG = """
import os, subprocess, time

def test_hangs_where_the_timeout_cannot_reach():
    child = subprocess.Popen(["sleep", "600"], start_new_session=True)
    with open(os.environ["CHILD_PID_FILE"], "w") as f:
        f.write(str(child.pid))
    for _ in range(600):  # a main thread that pytest-timeout's exception never ends, as one parked in Rust
        try:
            time.sleep(1)
        except BaseException:
            pass

def test_after_it_runs_on_a_new_worker():
    assert True
"""


# the suite's own scheduler (`make test`'s `--dist loadgroup`), loaded from this tree's tests/conftest.py
UNITS = """
import importlib.util

_spec = importlib.util.spec_from_file_location("robofabric_tests_conftest", {conftest!r})
_mod = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_mod)
pytest_xdist_make_scheduler = _mod.pytest_xdist_make_scheduler
"""


@pytest.mark.slow
@pytest.mark.timeout(120)
@pytest.mark.parametrize("dist", ["load", "loadgroup"])
def test_a_hung_test_is_ended_with_its_stacks_said_its_processes_killed_and_the_run_goes_on(
    tmp_path: Path, dist: str
) -> None:
    """On ``make test``'s ``loadgroup`` too, with the suite's scheduler (tests/conftest.py, ``remove_node``): xdist's
    own put the crashed test back in line, to hang again on each replacement; and the other worker ends first, so a
    scheduler that lost count of the collections never ends the run."""
    suite = tmp_path / "suite"
    suite.mkdir()
    (suite / "test_hung.py").write_text(textwrap.dedent(HUNG))
    # a worker that ends first
    (suite / "test_other.py").write_text("def test_on_the_other_worker():\n    assert True\n")
    conftest = Path(__file__).resolve().parents[1] / "conftest.py"
    (suite / "conftest.py").write_text(UNITS.format(conftest=str(conftest)))
    repo = str(Path(__file__).resolve().parents[2])  # this tree's robofabric, wherever the venv's install points
    env = {
        **os.environ,
        "ROBOFABRIC_HANG_GRACE_S": "2",
        "PYTHONPATH": repo,
        "CHILD_PID_FILE": str(tmp_path / "child.pid"),
    }
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "pytest",
            "-q",
            "-p",
            "robofabric.pytest_hang_watch",
            "-p",
            "no:cacheprovider",
            "-n",
            "2",
            "--dist",
            dist,
            "--timeout",
            "2",
            f"--basetemp={tmp_path / 'base'}",
            str(suite),
        ],
        capture_output=True,
        text=True,
        timeout=100,
        env=env,
        cwd=suite,
    )
    out = run.stdout + run.stderr
    assert run.returncode == 1, out
    assert "+++ hang watch: test_hung.py::test_hangs_where_the_timeout_cannot_reach still running 4 s" in out, out
    assert "test_hangs_where_the_timeout_cannot_reach" in out.split("+++ hang watch")[1], out  # its stack
    assert f"exits {HUNG_EXIT}" in out and "crashed" in out, out
    assert "1 failed, 2 passed" in out and "INTERNALERROR" not in out, out
    pid = int((tmp_path / "child.pid").read_text())
    assert not Path(f"/proc/{pid}").exists() or "Z" in Path(f"/proc/{pid}/stat").read_text().split(")")[1][:3], (
        f"its child {pid} still runs"
    )
