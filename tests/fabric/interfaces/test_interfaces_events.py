"""Event kinds: every kind robofabric sends is a named EventKind, and a member travels as its plain string."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from fabric.codec import decode, encode
from fabric.interfaces import REJECT_KINDS, Event, EventKind
from ownership import state as own_state

ROOT = Path(__file__).resolve().parents[3]
PACKAGES = ("fabric", "sim_peer", "compute_peer", "user_peer", "ownership", "robofabric")


def test_a_member_is_its_string_on_the_wire_and_in_the_message():
    ev = Event(kind=EventKind.REJECT, reason="not_owner", object="arm1", user="bob")
    assert type(ev.kind) is str and ev.kind == "reject"
    assert encode(ev) == encode(Event(kind="reject", reason="not_owner", object="arm1", user="bob"))
    assert decode(encode(ev), Event).kind == EventKind.REJECT
    assert "reject" in REJECT_KINDS and EventKind.REJECT in REJECT_KINDS


def test_every_ownership_change_the_authority_announces_has_a_kind():
    # the effects ownership.authority publishes as events (the others are answers to the requester)
    for effect in ("handover", "revoked", "expired", "restored", "released"):
        assert EventKind.ownership(effect) == f"own_{effect}"
    with pytest.raises(ValueError):
        EventKind.ownership("made_up")
    assert own_state.Effect("handover").kind == "handover"


def _literal_kinds(tree: ast.AST) -> list[tuple[int, str]]:
    """(line, text) of ``Event(kind="...")``, ``self._event("...", ...)`` and ``Note("...", ...)`` (a sim robot's
    event) calls with a string literal kind."""
    out = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        name = getattr(node.func, "id", None) or getattr(node.func, "attr", None)
        if name == "Event":
            for kw in node.keywords:
                if kw.arg == "kind" and isinstance(kw.value, (ast.Constant, ast.JoinedStr)):
                    out.append((node.lineno, ast.unparse(kw.value)))
        elif name in ("_event", "Note") and node.args and isinstance(node.args[0], (ast.Constant, ast.JoinedStr)):
            out.append((node.lineno, ast.unparse(node.args[0])))
    return out


def test_no_sender_spells_a_kind_as_a_string():
    found = []
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            for line, text in _literal_kinds(ast.parse(path.read_text(), str(path))):
                found.append(f"{path.relative_to(ROOT)}:{line}: {text}")
    assert not found, "event kinds spelt as strings (use fabric.interfaces.EventKind):\n" + "\n".join(found)


def test_the_scan_finds_a_literal_kind():
    tree = ast.parse(
        'Event(kind="reject")\nself._event("clamp", rid, "x")\nEvent(kind=f"own_{k}")\nEvent(kind=EventKind.REJECT)\n'
        'Note("collision", "bumper")\nNote(EventKind.PATH_DONE, "done")'
    )
    assert [t for _, t in _literal_kinds(tree)] == ["'reject'", "'clamp'", "f'own_{k}'", "'collision'"]


def _literal_matches(tree: ast.AST) -> list[tuple[int, str]]:
    """(line, text) of comparisons of a ``kind`` (name or attribute) with a string literal that is an event kind:
    ``note.kind == "collision"``, ``kind in ("reject", "clamp")`` (a robot's kind, ``"arm"``, is no event kind)."""
    kinds = {k.value for k in EventKind}

    def strings(n: ast.AST) -> list[str]:
        if isinstance(n, ast.Constant) and isinstance(n.value, str):
            return [n.value]
        if isinstance(n, (ast.Tuple, ast.List, ast.Set)):
            return [v for e in n.elts for v in strings(e)]
        return []

    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare):
            operands = [node.left, *node.comparators]
            if any(
                (isinstance(o, ast.Attribute) and o.attr == "kind") or (isinstance(o, ast.Name) and o.id == "kind")
                for o in operands
            ) and any(v in kinds for o in operands for v in strings(o)):
                out.append((node.lineno, ast.unparse(node)))
    return out


def test_no_reader_matches_a_kind_as_a_string():
    found = []
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            for line, text in _literal_matches(ast.parse(path.read_text(), str(path))):
                found.append(f"{path.relative_to(ROOT)}:{line}: {text}")
    assert not found, "event kinds matched as strings (use fabric.interfaces.EventKind):\n" + "\n".join(found)


def test_the_scan_finds_a_literal_match():
    tree = ast.parse(
        'n.kind == "collision"\nkind in ("reject", "x")\nr.kind == "arm"\nn.kind == EventKind.COLLISION\n'
        '"path_done" != ev.kind\nname == "clamp"'
    )
    assert [t for _, t in _literal_matches(tree)] == [
        "n.kind == 'collision'",
        "kind in ('reject', 'x')",
        "'path_done' != ev.kind",
    ]
