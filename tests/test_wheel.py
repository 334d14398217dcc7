"""The built wheel carries everything ``robofabric`` needs at run time: install it, run ``robofabric demo``.

The wheel is built from a copy of the source tree (no stale ``build/``, no ``examples/`` or ``tests/``
reachable from where it runs) and installed into a fresh virtual environment with ``--no-deps``.
Its dependencies are not downloaded and installed a second time (hundreds of MB: MuJoCo, Pinocchio,
CasADi, OMPL, Rerun): the fresh environment sees the test environment's site-packages through a
``.pth`` line, which adds that directory to ``sys.path`` without running its ``.pth`` files; those
are copied over (cmeel's, which puts Pinocchio on the path) except the editable install's, so this
checkout stays out of the picture. The test checks that the code it ran
came from the wheel, and that the wheel's declared requirements are met there.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

from robofabric.testing import free_port

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[1]
CAP_S = 90
_SKIP_ANYWHERE = shutil.ignore_patterns(
    "__pycache__", "*.egg-info", ".pytest_cache", ".hypothesis", "*.mcap", "*.rrd", "*.whl"
)
_SKIP_AT_TOP = {
    ".venv",
    ".git",
    "build",
    "dist",
    "out",
    "tests",
    "docs",
    "tools",
}  # the checkout's, not robofabric/tools


def _SKIP(folder: str, names: list[str]) -> set[str]:
    skipped = set(_SKIP_ANYWHERE(folder, names))
    return skipped | (_SKIP_AT_TOP & set(names)) if Path(folder) == REPO else skipped


def _run(argv: list[str], *, cwd: Path, timeout: float, env: dict | None = None) -> subprocess.CompletedProcess:
    out = subprocess.run(argv, cwd=cwd, capture_output=True, text=True, timeout=timeout, env=env)
    assert out.returncode == 0, (
        f"{' '.join(map(str, argv))} exited {out.returncode}:\n{(out.stdout + out.stderr)[-5000:]}"
    )
    return out


def test_wheel_installs_into_a_fresh_venv_and_runs_the_demo(tmp_path: Path) -> None:
    src = tmp_path / "src"
    shutil.copytree(REPO, src, ignore=_SKIP, symlinks=True)
    dist = tmp_path / "dist"
    _run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(dist), str(src)], cwd=tmp_path, timeout=300
    )
    wheels = sorted(dist.glob("robofabric-*.whl"))
    assert len(wheels) == 1, wheels

    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], cwd=tmp_path, timeout=120)
    py = venv / "bin" / "python"
    fresh_site = Path(
        _run(
            [str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], cwd=tmp_path, timeout=60
        ).stdout.strip()
    )
    deps_site = Path(sysconfig.get_paths()["purelib"])
    (fresh_site / "00-robofabric-test-deps.pth").write_text(f"{deps_site}\n")
    for pth in deps_site.glob("*.pth"):  # e.g. cmeel.pth, which puts Pinocchio's prefix on the path
        if not pth.name.startswith("__editable__"):
            shutil.copy(pth, fresh_site / pth.name)
    _run(
        [sys.executable, "-m", "pip", "--python", str(py), "install", "-q", "--no-deps", "--no-index", str(wheels[0])],
        cwd=tmp_path,
        timeout=300,
    )

    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env["PATH"] = f"{venv / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    where = _run(
        [
            str(py),
            "-c",
            "import fabric, robots, robofabric; print(fabric.__file__); print(robots.__file__); print(robofabric.__version__)",
        ],
        cwd=tmp_path,
        timeout=60,
        env=env,
    ).stdout.split()
    assert all(p.startswith(str(fresh_site)) for p in where[:2]), where  # the wheel's code, not this checkout's
    # Every requirement the wheel declares is installed at a version it accepts.
    check = (
        "from importlib.metadata import requires, version\n"
        "from packaging.requirements import Requirement\n"
        "bad = []\n"
        "for r in map(Requirement, requires('robofabric')):\n"
        "    if r.marker is not None and not r.marker.evaluate({'extra': ''}):\n"
        "        continue\n"
        "    if version(r.name) not in r.specifier:\n"
        "        bad.append(f'{r} (have {version(r.name)})')\n"
        "print('unmet:', bad) if bad else print('requirements met')\n"
        "raise SystemExit(1 if bad else 0)\n"
    )
    _run([str(py), "-c", check], cwd=tmp_path, timeout=60, env=env)

    robofabric = venv / "bin" / "robofabric"
    ver = _run([str(robofabric), "--version"], cwd=tmp_path, timeout=60, env=env).stdout.strip()
    assert ver == f"robofabric {where[2]}" and ver != "robofabric 0+unknown", ver

    out = tmp_path / "demo"
    port = free_port()
    run = subprocess.run(
        [str(robofabric), "demo", "--duration", str(CAP_S), "--out", str(out), "--router", f"tcp/127.0.0.1:{port}"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=CAP_S + 120,
        env=env,
    )
    text = run.stdout + run.stderr
    assert run.returncode == 0, text[-5000:]
    assert "site-packages" in text and "demo.toml" in text, text[-3000:]  # the launch file came from the install
    assert "all tasks finished" in run.stdout and run.stdout.splitlines()[-1].strip() == "ok", text[-3000:]
    assert (out / "demo.mcap").stat().st_size > 10_000 and (out / "demo.rrd").stat().st_size > 10_000
