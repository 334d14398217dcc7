"""A student's install (no extras): the user side imports and runs without the sim's and the compute peer's
stacks, and ``robofabric sim`` / ``robofabric compute`` name the extra to install.

The missing install is the one fake here: each subprocess gets a ``sitecustomize`` whose meta path finder
refuses MuJoCo, Pinocchio, CasADi and OMPL (and cmeel's Pinocchio prefix), as if pip had never installed them.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from fabric.extras import EXTRAS

pytestmark = pytest.mark.slow  # each test starts a Python process

REPO = Path(__file__).resolve().parents[2]
HEAVY = sorted(
    {m for mods in EXTRAS.values() for m in mods} | {"mujoco", "pinocchio", "casadi", "ompl", "hppfcl", "coal"}
)

BLOCKER = f"""
import importlib.abc, sys
class _NotInstalled(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in {HEAVY!r}:
            raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)
        return None
sys.meta_path.insert(0, _NotInstalled())
"""


def _student(tmp_path: Path, *argv: str, timeout: float = 120) -> subprocess.CompletedProcess:
    (tmp_path / "sitecustomize.py").write_text(BLOCKER)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), str(REPO)])}
    return subprocess.run(
        [sys.executable, *argv], capture_output=True, text=True, timeout=timeout, env=env, cwd=tmp_path
    )


def test_the_blocker_blocks(tmp_path):
    out = _student(tmp_path, "-c", "import mujoco")
    assert out.returncode != 0 and "No module named 'mujoco'" in out.stderr


@pytest.mark.parametrize(
    "command, extra, names", [("sim", "sim", "mujoco"), ("compute", "compute", "pinocchio, casadi, ompl")]
)
def test_a_peer_without_its_extra_says_which_to_install(tmp_path, command, extra, names):
    out = _student(tmp_path, "-m", "robofabric.cli", command, "--world", "w", "--connect", "tcp/127.0.0.1:9")
    assert out.returncode == 2, out.stdout + out.stderr
    lines = [ln for ln in (out.stdout + out.stderr).splitlines() if ln.strip()]
    assert any(f"needs {names}" in ln and f"pip install 'robofabric[{extra}]'" in ln for ln in lines), lines
    assert "Traceback" not in out.stderr, out.stderr


STUDENT_SURFACE = f"""
import user_peer, user_peer.world, user_peer.robot, user_peer.tui, user_peer.console.server, user_peer.console.page
import user_peer.console.state, user_peer.urdf_chain, ownership.client, fabric.session, robots, robofabric.cli
import numpy as np, sys
from user_peer.console.state import arm_links
links = arm_links("meca500", np.zeros(6), (0.0, 0.0, 0.0, 0.0))  # the console draws an arm without Pinocchio
assert len(links) == 8, links
heavy = sorted(m for m in sys.modules if m.split('.')[0] in {HEAVY!r})
print("heavy:", heavy)
"""


def test_the_student_surface_imports_without_the_sim_and_compute_stacks(tmp_path):
    out = _student(tmp_path, "-c", STUDENT_SURFACE)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "heavy: []" in out.stdout, out.stdout


def test_the_cli_lists_its_commands_on_a_students_install(tmp_path):
    out = _student(tmp_path, "-m", "robofabric.cli", "--help")
    assert out.returncode == 0, out.stderr
    for command in ("console", "user", "sim", "compute"):
        assert command in out.stdout
