"""What ``robofabric`` does before any command runs: annotations resolved once, typer's help renderer
loaded without markdown-it and pygments. Each check runs in a child interpreter (module state is global)."""

from __future__ import annotations

import subprocess
import sys

import pytest

pytestmark = pytest.mark.slow  # child interpreters


def _py(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)


_HELP = """
import sys
import robofabric.cli as fc
fc.load_plugins()
if {fast}:
    fc.resolve_annotations(fc.app)
    fc.defer_rich_extras()
try:
    fc.app(args={args!r}, prog_name="robofabric")
except SystemExit:
    pass
print("LOADED", "rich.markdown" in sys.modules, "rich.traceback" in sys.modules, file=sys.stderr)
"""


@pytest.mark.parametrize("args", [["--help"], ["ps", "--help"], ["own", "list", "--help"], ["record", "--help"]])
def test_help_is_the_same_with_annotations_resolved_and_rich_extras_deferred(args):
    plain = _py(_HELP.format(fast=False, args=args))
    fast = _py(_HELP.format(fast=True, args=args))
    assert plain.returncode == 0 and fast.returncode == 0, plain.stderr + fast.stderr
    assert fast.stdout == plain.stdout and "Usage: robofabric" in fast.stdout
    assert "LOADED False False" in fast.stderr, fast.stderr  # neither markdown-it nor pygments was imported


def test_deferred_classes_are_the_real_ones_on_first_use():
    out = _py(
        "import sys, robofabric.cli as fc\n"
        "fc.defer_rich_extras()\n"
        "import typer.rich_utils as r\n"
        "assert 'rich.markdown' not in sys.modules\n"
        "import rich.markdown, rich.traceback\n"
        "assert type(r.Markdown('# x')) is rich.markdown.Markdown\n"
        "assert r.Traceback.from_exception.__func__ is rich.traceback.Traceback.from_exception.__func__\n"
        "print('ok')\n"
    )
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr


def test_robofabric_help_loads_no_markdown_pygments_numpy_or_peer():
    """What `robofabric --help` must not import (its CPU budget is 0.3 s: docs/benchmarks.md)."""
    out = _py(
        "import sys\n"
        "from robofabric.cli import main\n"
        "code = main(['--help'])\n"
        "heavy = sorted(m for m in ('markdown_it', 'pygments', 'numpy', 'mujoco', 'rerun', 'textual', 'fabric.session', 'user_peer.api')"
        " if m in sys.modules)\n"
        "print('HEAVY', code, heavy, file=sys.stderr)\n"
    )
    assert "HEAVY 0 []" in out.stderr, out.stderr[-2000:]
