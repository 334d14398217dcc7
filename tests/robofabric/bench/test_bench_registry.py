"""The one registry of benchmarks: every benchmark module is in it, the CLI is built from it, the docs quote it."""

from __future__ import annotations

import importlib
import pkgutil
import subprocess
from pathlib import Path

import pytest
from typer.testing import CliRunner

import robofabric.bench
from robofabric.testing import robofabric_cmd
from robofabric.bench import BENCHMARKS, Benchmark, get, names
from robofabric.bench.cli import build_app, run_all

ROOT = Path(__file__).resolve().parents[3]


def test_every_benchmark_module_is_registered_once():
    modules = {}
    for info in pkgutil.iter_modules(robofabric.bench.__path__):
        mod = importlib.import_module(f"robofabric.bench.{info.name}")
        if callable(getattr(mod, "command", None)):
            modules[info.name] = mod.command
    registered = [b.module for b in BENCHMARKS]
    assert sorted(registered) == sorted(modules), "a module with a `command` that is not in BENCHMARKS, or the reverse"
    assert len(set(names())) == len(names()) and not {"all", "list"} & set(names())
    for b in BENCHMARKS:
        assert b.command() is modules[b.module]
        assert b.out in ("append", "write", "dir", "") and b.needs in ("", "netns")
    with pytest.raises(KeyError, match="known: transport"):
        get("warp")


def test_no_benchmark_is_left_in_the_other_packages():
    for pkg in ("fabric", "ownership", "sim_peer", "compute_peer", "user_peer", "robots", "tools"):
        strays = [p for p in (ROOT / pkg).rglob("*.py") if "bench" in p.name]
        assert not strays, strays


def test_the_bench_group_lists_every_benchmark_and_nothing_else():
    runner = CliRunner()
    app = build_app()
    res = runner.invoke(app, ["--help"])
    assert res.exit_code == 0, res.output
    for name in [*names(), "list", "all"]:
        assert f" {name} " in res.output, name
    res = runner.invoke(app, ["list"])
    assert res.exit_code == 0
    for b in BENCHMARKS:
        assert b.measures in res.output and "robofabric " + " ".join(b.argv()) in res.output
    for name in names():
        res = runner.invoke(app, [name, "--help"])
        assert res.exit_code == 0 and "Usage" in res.output, name


@pytest.mark.slow
def test_the_installed_cli_reaches_the_registry():
    """``robofabric bench`` comes through the entry point ``bench`` only: its commands are exactly the registry's."""
    import click
    import typer

    out = subprocess.run(robofabric_cmd("bench", "--help"), capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    for name in names():
        assert name in out.stdout
    from importlib.metadata import entry_points

    (ep,) = [e for e in entry_points(group="robofabric.commands") if e.name == "bench"]
    root = typer.Typer()
    ep.load()(root)
    group = typer.main.get_command(root)
    bench = group.commands["bench"]
    ctx = click.Context(bench)
    assert sorted(bench.list_commands(ctx)) == sorted([*names(), "list", "all"])
    # each benchmark's module is imported when it is named, not when the CLI starts
    assert all(bench.get_command(ctx, n).name == n for n in names())


def test_docs_quote_each_benchmarks_command_line():
    """docs/benchmarks.md's figures name the command that measured them: the registry's ``full`` arguments."""
    text = (ROOT / "docs" / "benchmarks.md").read_text()
    for b in BENCHMARKS:
        line = "robofabric " + " ".join(b.argv())
        assert f"`{line}" in text, line


def test_bench_all_rejects_unknown_names():
    res = CliRunner().invoke(build_app(), ["all", "--only", "warp"])
    assert res.exit_code != 0 and "unknown benchmark(s) warp" in str(res.exception)


@pytest.mark.slow
def test_bench_all_runs_the_quick_forms_and_collects_tables(tmp_path):
    out = tmp_path / "all.md"
    broken = Benchmark("transport", "transport", "a benchmark given a bad option", quick=("--rates", "x"))
    outcomes = run_all([get("sim"), get("nav"), broken], quick=True, out=out, progress=lambda s: None)
    assert [(o.name, o.returncode) for o in outcomes] == [("sim", 0), ("nav", 0), ("transport", 2)]
    text = out.read_text()
    assert text.startswith("# robofabric benchmarks") and "Machine: " in text
    assert "## `robofabric bench sim --seconds 1 --counts 1,5`" in text and "| combined (Meca500" in text
    assert "## `robofabric bench nav --queries 3 --scans 50`" in text and "| hybrid_astar | dubins |" in text
    assert "FAILED (exit 2)" in text and "--rates" in text


def test_bench_list_json_is_one_document_naming_every_benchmark():
    import json

    out = CliRunner().invoke(build_app(), ["list", "--json", "--quick"])
    assert out.exit_code == 0, out.output
    doc = json.loads(out.output)
    assert [b["name"] for b in doc["benchmarks"]] == list(names())
    assert all(
        b["argv"] == get(b["name"]).argv(quick=True) and set(b) == {"name", "measures", "needs", "argv"}
        for b in doc["benchmarks"]
    )
