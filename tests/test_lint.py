"""The tree passes its linter, its formatter's check and its type checker, with the settings of pyproject.toml,
and each does bite.

``ruff check`` (``[tool.ruff]``: pyflakes, pycodestyle's errors and warnings, bugbear, pyupgrade...) and
``ruff format --check`` (the formatter, 120 columns) take about 0.5 s of CPU each for the whole tree; ``mypy``
(``[tool.mypy]``: strict on ``fabric``, ``ownership`` and the pure cores) about 20 s when its cache
(``.mypy_cache``) is cold and about 1 s warm. They are programs of their own, so these tests are slow (the fast
suite runs in-process tests only). The tests that give each tool one small file breaking a rule make a
configuration that checks nothing (a wrong path, a rule set that selects nothing) fail here.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent


def _run(tool: str, *args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(BIN / tool), *args], cwd=cwd, capture_output=True, text=True, timeout=600)


def test_ruff_passes_on_the_tree():
    """``ruff check`` with the project's rules finds nothing (fix what it names; never widen the ignores to pass)."""
    out = _run("ruff", "check", "--no-cache", ".")
    assert out.returncode == 0, out.stdout + out.stderr


def test_ruff_names_an_unused_import_and_a_blind_exception_assert(tmp_path):
    """The project's rules bite: an unused import (F401) and ``pytest.raises(Exception)`` (B017) are named."""
    bad = tmp_path / "bad.py"
    bad.write_text(
        '"""A module that breaks two rules."""\n\nimport os\nimport pytest\n\n\n'
        "def test_x():\n    with pytest.raises(Exception):\n        pass\n"
    )
    out = _run("ruff", "check", "--no-cache", "--config", str(ROOT / "pyproject.toml"), str(bad), cwd=tmp_path)
    assert out.returncode == 1, out.stdout + out.stderr
    assert "F401" in out.stdout and "B017" in out.stdout, out.stdout


def test_the_tree_is_formatted():
    """``ruff format --check``: the tree is as ruff's formatter writes it (``[tool.ruff]``'s 120 columns); run
    ``ruff format .`` (``make format``) before committing."""
    out = _run("ruff", "format", "--check", "--no-cache", ".")
    assert out.returncode == 0, out.stdout + out.stderr


def test_the_format_check_bites(tmp_path):
    """A file the formatter would write otherwise (single quotes, a cramped call) fails the check, and is named."""
    bad = tmp_path / "cramped.py"
    bad.write_text('"""Cramped."""\n\nx = {\'a\':1,\'b\' :2}\nprint( x )\n')
    out = _run(
        "ruff", "format", "--check", "--no-cache", "--config", str(ROOT / "pyproject.toml"), str(bad), cwd=tmp_path
    )
    assert out.returncode == 1, out.stdout + out.stderr
    assert "cramped.py" in out.stdout + out.stderr, out.stdout + out.stderr


def test_mypy_passes_on_the_strict_modules():
    """``mypy`` with ``[tool.mypy]`` (its ``files``: fabric, ownership, robots/kinds.py and the sim's pure modules) finds nothing."""
    out = _run("mypy")
    assert out.returncode == 0, out.stdout + out.stderr
    assert "Success" in out.stdout, out.stdout


def test_mypy_is_strict(tmp_path):
    """The configuration is strict: a function without annotations and a bare ``dict`` are errors."""
    bad = tmp_path / "loose.py"
    bad.write_text('"""Loosely typed."""\n\n\ndef f(x):\n    return x\n\n\ndef g(d: dict) -> int:\n    return len(d)\n')
    out = _run(
        "mypy",
        "--config-file",
        str(ROOT / "pyproject.toml"),
        "--cache-dir",
        str(tmp_path / "cache"),
        str(bad),
        cwd=tmp_path,
    )
    assert out.returncode == 1, out.stdout + out.stderr
    assert "[no-untyped-def]" in out.stdout and "[type-arg]" in out.stdout, out.stdout
