"""The house's size rules hold on the code, and the check bites.

No module over 500 lines in any package, no class over 20 methods (frozen dataclasses, the value objects,
aside), no function over 80 lines outside the benchmarks (``robofabric/bench``): a module, class or
function past them holds more than one concern and is split by concern (issue 34). ``test_the_house_holds``
walks the packages and names every offender; ``test_the_check_bites`` runs it on a small tree with one of
each, so a check that could never fail fails here.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("fabric", "sim_peer", "compute_peer", "user_peer", "ownership", "robots", "robofabric")
BENCHMARKS = ("robofabric/bench",)  # long functions allowed: a benchmark reads best as one script
MAX_MODULE_LINES = 500
MAX_METHODS = 20
MAX_FUNCTION_LINES = 80


def _frozen_value(cls: ast.ClassDef) -> bool:
    """A ``@dataclass(frozen=True)`` (or ``@dataclasses.dataclass(frozen=True, ...)``)."""
    for d in cls.decorator_list:
        if isinstance(d, ast.Call) and getattr(d.func, "id", getattr(d.func, "attr", "")) == "dataclass":
            if any(kw.arg == "frozen" and isinstance(kw.value, ast.Constant) and kw.value.value is True for kw in d.keywords):
                return True
    return False


def offenders(root: Path, packages: tuple[str, ...] = PACKAGES, benchmarks: tuple[str, ...] = BENCHMARKS) -> list[str]:
    """Every module, class and function of ``packages`` under ``root`` past the rules, as ``path[:line] what``."""
    out = []
    for pkg in packages:
        modules = sorted((root / pkg).rglob("*.py"))
        assert modules, f"no package {pkg} under {root}"  # a check of nothing would pass
        for path in modules:
            rel = path.relative_to(root).as_posix()
            src = path.read_text(encoding="utf-8")
            lines = len(src.splitlines())
            if lines > MAX_MODULE_LINES:
                out.append(f"{rel} module of {lines} lines")
            in_bench = any(rel == b or rel.startswith(b + "/") for b in benchmarks)
            for node in ast.walk(ast.parse(src, rel)):
                if isinstance(node, ast.ClassDef) and not _frozen_value(node):
                    methods = sum(isinstance(b, (ast.FunctionDef, ast.AsyncFunctionDef)) for b in node.body)
                    if methods > MAX_METHODS:
                        out.append(f"{rel}:{node.lineno} class {node.name} of {methods} methods")
                elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and not in_bench:
                    n = node.end_lineno - node.lineno + 1
                    if n > MAX_FUNCTION_LINES:
                        out.append(f"{rel}:{node.lineno} function {node.name} of {n} lines")
    return out


def test_the_house_holds():
    found = offenders(ROOT)
    assert not found, "split these by concern (docs/architecture.md):\n" + "\n".join(found)


def _methods(n: int) -> str:
    return "".join(f"    def m{i}(self) -> None:\n        pass\n\n" for i in range(n))


def _function(name: str, body_lines: int) -> str:
    return f"def {name}() -> None:\n" + "    x = 0\n" * (body_lines - 1) + "\n"


def test_the_check_bites(tmp_path):
    (tmp_path / "pkg" / "bench").mkdir(parents=True)
    (tmp_path / "pkg" / "big.py").write_text("x = 1\n" * 501)
    (tmp_path / "pkg" / "classes.py").write_text(
        "from dataclasses import dataclass\n\n\nclass Wide:\n" + _methods(21)
        + "\nclass Twenty:\n" + _methods(20)
        + "\n@dataclass(frozen=True)\nclass Value:\n" + _methods(25))
    (tmp_path / "pkg" / "funcs.py").write_text(_function("long", 81) + _function("fits", 80))
    (tmp_path / "pkg" / "bench" / "run.py").write_text(_function("script", 120) + "class Wide:\n" + _methods(21))
    found = offenders(tmp_path, ("pkg",), ("pkg/bench",))
    assert found == [
        "pkg/bench/run.py:122 class Wide of 21 methods",
        "pkg/big.py module of 501 lines",
        "pkg/classes.py:4 class Wide of 21 methods",
        "pkg/funcs.py:1 function long of 81 lines",
    ], found
