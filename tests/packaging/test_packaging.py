"""The console script's own duties: version, shell completion, the packaged demo, and the 'fabric' name clash."""

from __future__ import annotations

import os
import subprocess
import sys
from importlib.metadata import version
from pathlib import Path

import pytest

from robofabric.launch_cli import load_demo_spec
from robofabric.clash import fabric_clash

REPO = Path(__file__).resolve().parents[2]


def _robofabric(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "robofabric", *args],
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ, **(env or {})},
    )


@pytest.mark.slow
def test_version_names_the_installed_distribution():
    out = _robofabric("--version")
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == f"robofabric {version('robofabric')}"


@pytest.mark.slow
def test_shell_completion_completes_subcommands():
    # name the shell instead of letting typer detect it from the process tree (there is no shell under CI)
    script = _robofabric("--show-completion", "bash", env={"_TYPER_COMPLETE_TEST_DISABLE_SHELL_DETECTION": "1"})
    assert script.returncode == 0 and "_ROBOFABRIC_COMPLETE" in script.stdout, script.stdout + script.stderr
    out = _robofabric(env={"_ROBOFABRIC_COMPLETE": "complete_bash", "COMP_WORDS": "robofabric re", "COMP_CWORD": "1"})
    assert out.returncode == 0, out.stderr
    assert set(out.stdout.split()) >= {"record", "replay"}, out.stdout


def test_the_demo_launch_file_is_package_data_and_examples_links_to_it():
    spec = load_demo_spec()
    assert Path(spec.path).parent == Path(__import__("robofabric").__file__).parent
    assert {p.name for p in spec.peers} >= {"recorder", "sim", "compute", "view", "alice", "bob"}
    # examples/demo.toml is the same file (a link), so `robofabric up examples/demo.toml` is the demo.
    assert (REPO / "examples" / "demo.toml").resolve() == (REPO / "robofabric" / "demo.toml").resolve()


def _dist_info(where: Path, name: str, ver: str) -> None:
    d = where / f"{name}-{ver}.dist-info"
    d.mkdir(parents=True)
    (d / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: {ver}\n")


def test_clash_with_the_ssh_library_fabric_is_detected(tmp_path):
    _dist_info(tmp_path / "clean", "robofabric", "0.1.0")
    assert fabric_clash([str(tmp_path / "clean")]) is None
    _dist_info(tmp_path / "clash", "robofabric", "0.1.0")
    _dist_info(tmp_path / "clash", "fabric", "3.2.2")
    warning = fabric_clash([str(tmp_path / "clash")])
    assert (
        warning is not None and "'fabric' 3.2.2" in warning and "SSH" in warning and "pip uninstall fabric" in warning
    )


@pytest.mark.slow
def test_the_console_script_warns_at_start_when_fabric_is_installed(tmp_path):
    _dist_info(tmp_path, "fabric", "3.2.2")
    out = _robofabric("--version", env={"PYTHONPATH": str(tmp_path)})
    assert out.returncode == 0 and out.stdout.startswith("robofabric ")
    assert "SSH library Fabric" in out.stderr, out.stderr
    assert "SSH library" not in _robofabric("--version").stderr
