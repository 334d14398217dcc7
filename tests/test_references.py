"""Every file of this tree that the docs or the code name exists: a moved or deleted module, test or page leaves no
reference behind.

A reference is a path under one of the tree's top folders (``fabric/session.py``, ``docs/sim.md``,
``tests/sim_peer/replica/test_election.py``) or a test module's bare name (``test_election.py``), anywhere in the docs
(``docs/**/*.md``, ``README.md``) and in the Python files (docstrings, comments, strings). CHANGELOG.md is left out:
history names files as they were; so is this module, whose examples are made up. Placeholders (``robofabric/bench/NAME.py``) are no reference. A pure scan of
the text, about 0.2 s.
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TOPS = (
    "fabric",
    "ownership",
    "sim_peer",
    "compute_peer",
    "user_peer",
    "robofabric",
    "robots",
    "tests",
    "docs",
    "tools",
)
_SKIP_DIRS = {"node_modules", "__pycache__", ".venv", "build", "dist", ".git", ".mypy_cache", ".ruff_cache"}
REFERENCE = re.compile(rf"(?<![\w/.-])((?:{'|'.join(TOPS)})/(?:[\w-]+/)*[\w-]+\.(?:py|md)|test_\w+\.py)\b")

_SELF = "tests/test_references.py"
"""This module: its examples name made-up files."""

NOT_REFERENCES = {
    (
        "tests/test_layers.py",
        "compute_peer/service.py",
    ),  # a module of the made-up tree the layer contracts are tried on
    (
        "tests/test_layers.py",
        "sim_peer/stray.py",
    ),  # the made-up tree's module in no room of the sim (exhaustive layers)
    ("tests/robofabric/test_hang_watch.py", "test_hung.py"),  # the made-up suite the hang watch is tried on
    ("tests/robofabric/test_hang_watch.py", "test_other.py"),  # and the made-up module beside it
    # the made-up rooms the narrow-shells scan is tried on: a clean shell, and one taking the host each way
    ("tests/sim_peer/test_narrow_shells.py", "sim_peer/shards/clean.py"),
    ("tests/sim_peer/test_narrow_shells.py", "sim_peer/shards/param.py"),
    ("tests/sim_peer/test_narrow_shells.py", "sim_peer/replica/attr.py"),
    ("tests/sim_peer/test_narrow_shells.py", "sim_peer/replica/typed.py"),
}
"""(file, what it names) pairs that name no file of this tree on purpose."""


def _files(root: Path) -> list[Path]:
    """The docs and the Python files of ``root``'s tree (not CHANGELOG.md, not installed or generated folders)."""
    out = [p for p in (root / "README.md",) if p.exists()]
    for top in TOPS:
        for p in sorted((root / top).rglob("*")):
            if (
                p.suffix in (".py", ".md")
                and p.is_file()
                and not _SKIP_DIRS & set(p.relative_to(root).parts)
                and p.relative_to(root).as_posix() != _SELF
            ):
                out.append(p)
    return out


def stale_references(root: Path) -> list[tuple[str, int, str]]:
    """(file, line, what it names) for each reference in ``root``'s tree to a file that is not there."""
    files = _files(root)
    paths = {p.relative_to(root).as_posix() for p in files}
    names = {p.name for p in files}
    out = []
    for p in files:
        rel = p.relative_to(root).as_posix()
        for n, line in enumerate(p.read_text(errors="replace").splitlines(), 1):
            for m in REFERENCE.finditer(line):
                ref = m.group(1)
                there = ref in paths if "/" in ref else ref in names
                if not there and "NAME" not in ref and (rel, ref) not in NOT_REFERENCES:
                    out.append((rel, n, ref))
    return out


def test_every_file_the_docs_and_the_code_name_exists():
    """No reference to a module, test or page that is not in the tree (fix the reference, or the name it should have)."""
    assert stale_references(ROOT) == []


def test_the_exceptions_are_still_there():
    """Each pair of ``NOT_REFERENCES`` still occurs: an exception nothing needs any more goes."""
    for rel, ref in NOT_REFERENCES:
        assert ref in (ROOT / rel).read_text(), (rel, ref)


def test_a_reference_to_a_file_that_is_gone_is_named(tmp_path):
    """The scan bites: in a small tree, a page naming a missing module and a missing test is reported with its line,
    and the names of files that are there are not."""
    (tmp_path / "docs").mkdir()
    (tmp_path / "fabric").mkdir()
    (tmp_path / "fabric" / "here.py").write_text('"""See tests/fabric/test_' + 'here.py."""\n')
    (tmp_path / "tests" / "fabric").mkdir(parents=True)
    (tmp_path / "tests" / "fabric" / "test_here.py").write_text("")
    gone, gone_test = "fabric/" + "gone.py", "test_" + "gone.py"
    (tmp_path / "docs" / "page.md").write_text(f"# Page\n\n`fabric/here.py` and `{gone}`,\nthen {gone_test}.\n")
    assert stale_references(tmp_path) == [("docs/page.md", 3, gone), ("docs/page.md", 4, gone_test)]
