"""The house's size figures, reported as warnings: what holds a package together is a contract, not a count.

Cohesion is enforced by the import-linter contracts (pyproject.toml, ``tests/test_layers.py``): a package's rooms
stand in one order. Sizes are only a hint that a module, class or function may hold more than one concern, so
they are reported, never failed on: a module over 500 lines in any package, a class that offers over 20 methods
(frozen dataclasses, the value objects, aside), a function over 80 lines outside the benchmarks
(``robofabric/bench``). Each offender is one ``HouseSizeWarning`` in pytest's warnings summary; a warning is a
prompt to look, and a module, class or function that holds one concern may stay as it is.

What a class offers is counted as its user meets it: its public methods (properties too), with those of its
mixins. A mixin is a base class of the packages without an ``__init__`` of its own: it works on its host's
state, so its methods are the host's (a mixin that only forwards to an attribute hid the host's size). A base
class with its own ``__init__`` (``Arm``'s ``Robot``) is a class of its own, counted where it is written.
Private helpers are the class's workings, bounded by the module's lines.

``test_the_house_sizes_are_reported`` walks the packages and warns once per offender; ``test_the_check_bites``
runs the walk on a small tree with one of each, so a check that could never find anything fails there, and
checks that each offender comes out as a ``HouseSizeWarning`` (and that a tree within the figures warns nothing).
"""

from __future__ import annotations

import ast
import warnings
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("fabric", "sim_peer", "compute_peer", "user_peer", "ownership", "robots", "robofabric")
BENCHMARKS = ("robofabric/bench",)  # long functions allowed: a benchmark reads best as one script
MAX_MODULE_LINES = 500
MAX_METHODS = 20
MAX_FUNCTION_LINES = 80


class HouseSizeWarning(UserWarning):
    """A module, class or function past the house's size figures: look whether it holds more than one concern."""


def _frozen_value(cls: ast.ClassDef) -> bool:
    """A ``@dataclass(frozen=True)`` (or ``@dataclasses.dataclass(frozen=True, ...)``)."""
    for d in cls.decorator_list:
        if isinstance(d, ast.Call) and getattr(d.func, "id", getattr(d.func, "attr", "")) == "dataclass":
            if any(
                kw.arg == "frozen" and isinstance(kw.value, ast.Constant) and kw.value.value is True
                for kw in d.keywords
            ):
                return True
    return False


def _module_name(rel: str) -> str:
    parts = rel.removesuffix(".py").split("/")
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imported(module: str, tree: ast.Module) -> dict[str, tuple[str, str]]:
    """The names ``from X import Name [as alias]`` binds in ``module``: alias -> (X, Name), X made absolute."""
    out = {}
    package = module.split(".")
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            base = node.module
            if node.level:  # relative: from the module's package up
                base = ".".join(package[: len(package) - node.level] + ([node.module] if node.module else []))
            for a in node.names:
                out[a.asname or a.name] = (base or "", a.name)
    return out


def _classes(trees: dict[str, ast.Module]) -> dict[tuple[str, str], tuple[ast.ClassDef, dict[str, tuple[str, str]]]]:
    """Every class of the modules ``trees`` (path -> tree) as (module, name) -> (its node, its module's
    imported names)."""
    out = {}
    for rel, tree in trees.items():
        module = _module_name(rel)
        imported = _imported(module, tree)
        for node in ast.walk(tree):
            if isinstance(node, ast.ClassDef):
                out[(module, node.name)] = (node, imported)
    return out


def _defs(cls: ast.ClassDef) -> list[str]:
    return [b.name for b in cls.body if isinstance(b, (ast.FunctionDef, ast.AsyncFunctionDef))]


def _bases(key: tuple[str, str], classes: dict) -> list[tuple[str, str]]:
    """The bases of the class ``key`` that are classes of ``classes`` (found in its module, or imported)."""
    node, imported = classes[key]
    found = [(key[0], n) if (key[0], n) in classes else imported.get(n) for n in map(ast.unparse, node.bases)]
    return [b for b in found if b in classes and b != key]


def _constructs(key: tuple[str, str], classes: dict) -> bool:
    """Whether the class ``key``, or a base of it in ``classes``, has an ``__init__``: a class of its own."""
    return "__init__" in _defs(classes[key][0]) or any(_constructs(b, classes) for b in _bases(key, classes))


def offered(key: tuple[str, str], classes: dict) -> set[str]:
    """The public methods the class ``key`` offers: its own, and its mixins' (its bases in ``classes`` that
    construct nothing: no ``__init__`` in them or their bases), theirs counted the same way."""
    names = {d for d in _defs(classes[key][0]) if not d.startswith("_")}
    for base in _bases(key, classes):
        if not _constructs(base, classes):
            names |= offered(base, classes)
    return names


def offenders(root: Path, packages: tuple[str, ...] = PACKAGES, benchmarks: tuple[str, ...] = BENCHMARKS) -> list[str]:
    """Every module, class and function of ``packages`` under ``root`` past the rules, as ``path[:line] what``."""
    out = []
    sources: dict[str, str] = {}
    for pkg in packages:
        modules = sorted((root / pkg).rglob("*.py"))
        assert modules, f"no package {pkg} under {root}"  # a check of nothing would pass
        sources.update((path.relative_to(root).as_posix(), path.read_text(encoding="utf-8")) for path in modules)
    trees = {rel: ast.parse(src, rel) for rel, src in sources.items()}
    classes = _classes(trees)
    for rel, src in sources.items():
        lines = len(src.splitlines())
        if lines > MAX_MODULE_LINES:
            out.append(f"{rel} module of {lines} lines")
        in_bench = any(rel == b or rel.startswith(b + "/") for b in benchmarks)
        for node in ast.walk(trees[rel]):
            if isinstance(node, ast.ClassDef) and not _frozen_value(node):
                methods = len(offered((_module_name(rel), node.name), classes))
                if methods > MAX_METHODS:
                    out.append(f"{rel}:{node.lineno} class {node.name} offers {methods} methods")
            elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and not in_bench:
                n = node.end_lineno - node.lineno + 1
                if n > MAX_FUNCTION_LINES:
                    out.append(f"{rel}:{node.lineno} function {node.name} of {n} lines")
    return out


def report(root: Path, packages: tuple[str, ...] = PACKAGES, benchmarks: tuple[str, ...] = BENCHMARKS) -> list[str]:
    """``offenders`` of ``root``, each also warned as a ``HouseSizeWarning``; never raises for a size."""
    found = offenders(root, packages, benchmarks)
    for what in found:
        warnings.warn(
            HouseSizeWarning(f"{what}: does it hold more than one concern? (docs/architecture.md)"), stacklevel=2
        )
    return found


@pytest.mark.slow  # seconds: every module of the packages parsed and walked (a report; it warns, never fails a size)
def test_the_house_sizes_are_reported():
    """A warning per offender (the packages are walked: ``offenders`` fails on a package that is not there)."""
    report(ROOT)


def _methods(n: int, prefix: str = "m") -> str:
    return "".join(f"    def {prefix}{i}(self) -> None:\n        pass\n\n" for i in range(n))


def _function(name: str, body_lines: int) -> str:
    return f"def {name}() -> None:\n" + "    x = 0\n" * (body_lines - 1) + "\n"


def test_the_check_bites(tmp_path):
    (tmp_path / "pkg" / "bench").mkdir(parents=True)
    (tmp_path / "pkg" / "big.py").write_text("x = 1\n" * 501)
    (tmp_path / "pkg" / "classes.py").write_text(
        "from dataclasses import dataclass\n\n\nclass Wide:\n"
        + _methods(21)
        + "\nclass Twenty:\n"
        + _methods(20)
        + "\n@dataclass(frozen=True)\nclass Value:\n"
        + _methods(25)
    )
    # a mixin's methods are its host's, through an import too; a base class with an __init__ is counted alone
    (tmp_path / "pkg" / "mixin.py").write_text("class Forwards:\n" + _methods(8, "f"))
    (tmp_path / "pkg" / "hosts.py").write_text(
        "from pkg.mixin import Forwards\n\n\nclass Host(Forwards):\n"
        + _methods(13)
        + "\nclass Fits(Forwards):\n"
        + _methods(12)
        + _methods(30, "_helper")
        + "\nclass Base:\n    def __init__(self) -> None:\n        pass\n\n"
        + _methods(15, "b")
        + "\nclass Kind(Base):\n"
        + _methods(15)
        + "\nclass Middle(Base):\n"
        + _methods(10, "i")
        + "\nclass Leaf(Middle):\n"
        + _methods(15)
    )
    (tmp_path / "pkg" / "funcs.py").write_text(_function("long", 81) + _function("fits", 80))
    (tmp_path / "pkg" / "bench" / "run.py").write_text(_function("script", 120) + "class Wide:\n" + _methods(21))
    with pytest.warns(HouseSizeWarning) as caught:
        found = report(tmp_path, ("pkg",), ("pkg/bench",))
    assert [str(w.message).split(": does it")[0] for w in caught] == found
    assert found == [
        "pkg/bench/run.py:122 class Wide offers 21 methods",
        "pkg/big.py module of 501 lines",
        "pkg/classes.py:4 class Wide offers 21 methods",
        "pkg/funcs.py:1 function long of 81 lines",
        "pkg/hosts.py:4 class Host offers 21 methods",
    ], found


def test_a_tree_within_the_figures_warns_nothing(tmp_path):
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "long.py").write_text("x = 1\n" * 500)
    (tmp_path / "pkg" / "fits.py").write_text("class Twenty:\n" + _methods(20) + _function("fits", 80))
    with warnings.catch_warnings():
        warnings.simplefilter("error", HouseSizeWarning)
        assert report(tmp_path, ("pkg",)) == []
