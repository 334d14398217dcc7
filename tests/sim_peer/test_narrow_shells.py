"""The replica's and shards' shells talk through narrow interfaces: none takes the ReplicaHost whole.

A shell gets what it uses in its constructor (the fabric, a stop flag, callables, a small Protocol) and a clock;
only ``replica_host.py`` composes them. A module that takes the host would have to be listed in :data:`TAKES_HOST`,
which is empty and may only stay so."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
ROOMS = ("sim_peer/replica", "sim_peer/shards")
COMPOSER = "sim_peer/replica/replica_host.py"
TAKES_HOST: set[str] = set()
"""Shells that still reach into the host: none."""


def host_uses(source: str) -> list[str]:
    """Where a module takes the host: a parameter or attribute named ``host``, or a name ``ReplicaHost``
    (an import, an annotation, a string annotation)."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.arg) and node.arg == "host":
            out.append(f"line {node.lineno}: parameter host")
        elif isinstance(node, ast.Attribute) and node.attr == "host":
            out.append(f"line {node.lineno}: attribute .host")
        elif isinstance(node, ast.Name) and node.id == "ReplicaHost":
            out.append(f"line {node.lineno}: ReplicaHost")
        elif isinstance(node, ast.alias) and node.name.split(".")[-1] in ("ReplicaHost", "replica_host"):
            out.append(f"line {node.lineno}: imports {node.name}")
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and _annotation_of_host(node.value):
            out.append(f"line {node.lineno}: annotation {node.value!r}")
    return out


def _annotation_of_host(text: str) -> bool:
    """Whether a string is an annotation naming the host (``"ReplicaHost"``), not prose that mentions it."""
    try:
        expr = ast.parse(text.strip(), mode="eval")
    except SyntaxError:
        return False
    return any(isinstance(n, ast.Name) and n.id == "ReplicaHost" for n in ast.walk(expr))


def shells_taking_the_host(root: Path) -> dict[str, list[str]]:
    """Every module of the replica's and shards' rooms under ``root`` that takes the host, but the composer."""
    found = {}
    for room in ROOMS:
        for path in sorted((root / room).glob("*.py")):
            rel = path.relative_to(root).as_posix()
            if rel != COMPOSER and (uses := host_uses(path.read_text())):
                found[rel] = uses
    return found


def test_no_shell_but_the_composer_takes_the_host():
    found = shells_taking_the_host(ROOT)
    assert {m: u for m, u in found.items() if m not in TAKES_HOST} == {}, "a shell takes the ReplicaHost again"
    assert TAKES_HOST - set(found) == set(), "narrowed: take it off TAKES_HOST"


def test_the_scan_bites_on_each_way_of_taking_the_host(tmp_path):
    (tmp_path / "sim_peer" / "replica").mkdir(parents=True)
    (tmp_path / "sim_peer" / "shards").mkdir(parents=True)
    (tmp_path / COMPOSER).write_text("class ReplicaHost:\n    pass\n")  # the composer may
    (tmp_path / "sim_peer/shards/clean.py").write_text(
        '"""Names the ReplicaHost in a docstring: that is no seam."""\n\n\nclass Part:\n'
        "    def __init__(self, fabric, clock):\n        self.fabric, self.clock = fabric, clock\n"
    )
    (tmp_path / "sim_peer/shards/param.py").write_text("class Part:\n    def __init__(self, host):\n        pass\n")
    (tmp_path / "sim_peer/replica/attr.py").write_text("def f(part):\n    return part.host.lock\n")
    (tmp_path / "sim_peer/replica/typed.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
        "    from sim_peer.replica.replica_host import ReplicaHost\n"
        "def f(h: 'ReplicaHost'):\n    pass\n"
    )
    found = shells_taking_the_host(tmp_path)
    assert set(found) == {"sim_peer/shards/param.py", "sim_peer/replica/attr.py", "sim_peer/replica/typed.py"}
    assert found["sim_peer/shards/param.py"] == ["line 2: parameter host"]
    assert any("imports" in u for u in found["sim_peer/replica/typed.py"])
    assert any("annotation" in u for u in found["sim_peer/replica/typed.py"])
