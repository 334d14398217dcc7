"""Documentation that runs: every ```bash, ```sh and ```python block in README.md and
docs/**/*.md runs against one live world and must exit 0 within a limit.

The convention every page follows:

- a block meant to be run is fenced ```bash, ```sh or ```python;
- a block that needs a LAN, a display, credentials or a long-running foreground process is preceded,
  on the line immediately before the fence, by ``<!-- not-run: REASON -->``;
- output, config excerpts and pseudo-code use ```text, ```toml, ```json5, ```console... (never run);
- every fence names its language: a bare one is an error (it hid commands from the runner before).

The world: a router hosted by this process, a sim peer (scene ``combined``) and a compute peer
(``--stream arm1:target``), on a loopback port of its own. Blocks see it through the environment:
``ROBOFABRIC_CONNECT`` and ``ROBOFABRIC_WORLD`` (which every command and ``user_peer.connect()`` read),
``PATH`` starting with this interpreter's ``bin`` (so ``robofabric`` and ``python`` are the ones under
test). Each block runs in a scratch folder holding links to the repository's top-level entries, so
relative paths such as ``examples/demo.toml`` work and nothing is written into the checkout.
A runnable block that names an address outside loopback fails before it runs: tests never contact a LAN.
"""

from __future__ import annotations

import ipaddress
import os
import re
import subprocess
import sys
import uuid
from dataclasses import dataclass
from pathlib import Path

import pytest

from fabric.session import Fabric
from robofabric.testing import ProcessGroup, free_port, robofabric_cmd, router_config, wait_until

ROOT = Path(__file__).resolve().parent.parent
RUN_LANGS = {"bash": "bash", "sh": "bash", "python": "python"}
NOT_RUN = re.compile(r"^\s*<!--\s*not-run:\s*(?P<reason>.*?)\s*-->\s*$")
FENCE = re.compile(r"^(?P<indent>\s*)(?P<fence>`{3,}|~{3,})(?P<info>[^`]*)$")
IPV4 = re.compile(r"(?<![\d.])(\d{1,3}(?:\.\d{1,3}){3})(?![\d.])")
LIMIT_S = 240.0  # per block; the slowest (drive, map, plan, follow) takes well under a minute


@dataclass(frozen=True)
class Block:
    """One fenced block of a page: where it starts (1-based line of the fence), its language, its
    text, and the reason it is not run ("" when it runs)."""

    path: str
    line: int
    lang: str
    code: str
    not_run: str = ""

    @property
    def runs(self) -> bool:
        return self.lang in RUN_LANGS and not self.not_run

    @property
    def id(self) -> str:
        return f"{self.path}:{self.line}"


class DocFormatError(ValueError):
    """A page breaks the convention (a marker without a fence, an empty reason, an unclosed fence)."""


def extract(text: str, path: str = "<text>") -> list[Block]:
    """The fenced blocks of a Markdown page, with their not-run markers; :class:`DocFormatError` when
    the page breaks the convention."""
    lines = text.splitlines()
    blocks: list[Block] = []
    i = 0
    while i < len(lines):
        m = NOT_RUN.match(lines[i])
        if m is not None:
            if not m.group("reason"):
                raise DocFormatError(f"{path}:{i + 1}: not-run marker without a reason")
            if i + 1 >= len(lines) or not FENCE.match(lines[i + 1]):
                raise DocFormatError(f"{path}:{i + 1}: not-run marker not on the line immediately before a fence")
        f = FENCE.match(lines[i])
        if f is None:
            i += 1
            continue
        fence, lang = f.group("fence"), f.group("info").strip().split(" ")[0].lower()
        start = i
        if not lang:  # a bare fence hides commands from the runner: every block says what it holds
            raise DocFormatError(
                f"{path}:{start + 1}: fence without a language (```bash or ```python to run, ```text for output)"
            )
        body: list[str] = []
        i += 1
        while i < len(lines) and not re.match(rf"^\s*{re.escape(fence[0])}{{{len(fence)},}}\s*$", lines[i]):
            body.append(lines[i][len(f.group("indent")) :] if lines[i].startswith(f.group("indent")) else lines[i])
            i += 1
        if i >= len(lines):
            raise DocFormatError(f"{path}:{start + 1}: fence never closed")
        prev = NOT_RUN.match(lines[start - 1]) if start > 0 else None
        blocks.append(Block(path, start + 1, lang, "\n".join(body) + "\n", prev.group("reason") if prev else ""))
        i += 1
    return blocks


def pages() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]


def all_blocks() -> list[Block]:
    out: list[Block] = []
    for page in pages():
        out += extract(page.read_text(encoding="utf-8"), str(page.relative_to(ROOT)))
    return out


def lan_addresses(code: str) -> list[str]:
    """IPv4 addresses in a block's code (comments aside: ``# or connect="tcp/10.0.0.5:7447"`` contacts
    nothing) that are neither loopback nor the wildcard (which only listens)."""
    out = []
    text = "\n".join(re.sub(r"(^|\s)#.*$", "", line) for line in code.splitlines())
    for a in IPV4.findall(text):
        try:
            ip = ipaddress.ip_address(a)
        except ValueError:
            continue
        if not (ip.is_loopback or ip.is_unspecified):
            out.append(a)
    return out


# ---------------------------------------------------------------------------- the convention (fast)


def test_extract_follows_the_convention():
    page = "\n".join(
        [
            "# T",
            "```bash",
            "robofabric ps",
            "```",
            "<!-- not-run: needs a LAN -->",
            "```python",
            "import x",
            "```",
            "```text",
            "out",
            "```",
            "````sh",
            "echo '```'",
            "````",
            "",
        ]
    )
    b = extract(page)
    assert [(x.line, x.lang, x.runs, x.not_run) for x in b] == [
        (2, "bash", True, ""),
        (6, "python", False, "needs a LAN"),
        (9, "text", False, ""),
        (12, "sh", True, ""),
    ]
    assert b[3].code == "echo '```'\n"
    with pytest.raises(DocFormatError, match="immediately before a fence"):
        extract("<!-- not-run: x -->\n\n```bash\nls\n```\n")
    with pytest.raises(DocFormatError, match="without a reason"):
        extract("<!-- not-run: -->\n```bash\nls\n```\n")
    with pytest.raises(DocFormatError, match="never closed"):
        extract("```bash\nls\n")
    with pytest.raises(DocFormatError, match="without a language"):
        extract("# T\n```\nrobofabric ps\n```\n")
    assert lan_addresses("connect tcp/10.0.0.5:7447, tcp/127.0.0.1:1 tcp/0.0.0.0:7447 v1.10.2") == ["10.0.0.5"]
    assert lan_addresses("x = 1  # or tcp/10.0.0.5:7447\n# 10.0.0.6\ny = 'tcp/10.0.0.7:1'") == ["10.0.0.7"]


def test_every_page_follows_the_convention_and_runs_no_lan_address():
    blocks = all_blocks()  # raises DocFormatError with file:line
    assert any(b.runs for b in blocks), "no runnable block found: is the extractor broken?"
    bad = [f"{b.id}: {', '.join(lan_addresses(b.code))}" for b in blocks if b.runs and lan_addresses(b.code)]
    assert not bad, (
        "runnable blocks name LAN addresses (mark them <!-- not-run: ... --> or read $ROBOFABRIC_CONNECT): "
        + "; ".join(bad)
    )


# ---------------------------------------------------------------------------- running them (slow)


@pytest.fixture(scope="module")
def docs_world(tmp_path_factory):
    """Router + sim + compute on loopback; yields the environment and the scratch folder blocks run in."""
    world = f"doc{uuid.uuid4().hex[:6]}"
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    logs = tmp_path_factory.mktemp("docs-logs")
    scratch = tmp_path_factory.mktemp("docs-run")
    for entry in ROOT.iterdir():
        if entry.name not in (".git", ".venv", "out") and not (scratch / entry.name).exists():
            (scratch / entry.name).symlink_to(entry)
    router = Fabric(router_config(world, port), kind="router", peer_id="router")
    procs = ProcessGroup(logs)
    try:
        sim = procs.start(robofabric_cmd("sim", "--scene", "combined", "--world", world, "--connect", ep), name="sim")
        wait_until(
            lambda: router.live_peers("sim"), timeout=90, what="sim peer", seen=lambda: procs.output(sim)[-2000:]
        )
        comp = procs.start(
            robofabric_cmd("compute", "--stream", "arm1:target", "--world", world, "--connect", ep), name="compute"
        )
        wait_until(
            lambda: router.live_peers("compute"),
            timeout=90,
            what="compute peer",
            seen=lambda: procs.output(comp)[-2000:],
        )
        bindir = str(Path(sys.executable).parent)
        env = {
            **os.environ,
            "ROBOFABRIC_CONNECT": ep,
            "ROBOFABRIC_WORLD": world,
            "PATH": bindir + os.pathsep + os.environ.get("PATH", ""),
            "PYTHONUNBUFFERED": "1",
            "MPLBACKEND": "Agg",
        }
        env.pop("ROBOFABRIC_PROFILE", None)
        env.pop("ROBOFABRIC_ZENOH_CONFIG", None)
        yield env, scratch, procs
    finally:
        procs.close()
        router.close()


RUNNABLE = [b for b in all_blocks() if b.runs]


@pytest.mark.slow
@pytest.mark.parametrize("block", RUNNABLE, ids=[b.id for b in RUNNABLE])
def test_doc_block_runs(block: Block, docs_world):
    env, scratch, _ = docs_world
    assert not lan_addresses(block.code), f"{block.id} names a LAN address"
    name = re.sub(r"[^A-Za-z0-9]+", "_", block.id)
    src = scratch / f"block_{name}.{'py' if RUN_LANGS[block.lang] == 'python' else 'sh'}"
    src.write_text(block.code, encoding="utf-8")
    argv = (
        [sys.executable, str(src)] if RUN_LANGS[block.lang] == "python" else ["bash", "-e", "-o", "pipefail", str(src)]
    )
    proc = subprocess.Popen(
        argv, cwd=scratch, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True
    )
    try:
        out, _ = proc.communicate(timeout=LIMIT_S)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, 9)
        out, _ = proc.communicate()
        pytest.fail(f"{block.id} ran past {LIMIT_S:.0f} s; output:\n{out.decode(errors='replace')[-3000:]}")
    text = out.decode(errors="replace")
    assert proc.returncode == 0, f"{block.id} exited {proc.returncode}:\n{block.code}\n--- output ---\n{text[-3000:]}"


# ---------------------------------------------------------------------------- the classroom notebook (slow)


@pytest.mark.slow
def test_classroom_notebook_runs(docs_world, monkeypatch):
    """examples/classroom.ipynb, executed by nbclient in a real kernel against the same world: join, own
    the arm, IK move, plot the joints, drive, map, plan, follow. Where the notebook extra is installed
    the inline Rerun view is created too (a widget output; no browser is needed to create it); without
    it the notebook says how to get it. ``tests/user_peer/test_notebook_view.py`` checks its drawing."""
    import nbformat
    from nbclient import NotebookClient

    env, scratch, _ = docs_world
    for k in ("ROBOFABRIC_CONNECT", "ROBOFABRIC_WORLD", "PATH"):
        monkeypatch.setenv(k, env[k])  # the kernel inherits this process's environment
    monkeypatch.delenv("ROBOFABRIC_NOTEBOOK_VIEW", raising=False)
    monkeypatch.delenv("MPLBACKEND", raising=False)  # the kernel's inline backend draws into the outputs
    nb = nbformat.read(ROOT / "examples" / "classroom.ipynb", as_version=4)
    assert not any(c.get("outputs") for c in nb.cells if c.cell_type == "code"), "commit the notebook without outputs"
    NotebookClient(
        nb, timeout=int(LIMIT_S), kernel_name="python3", resources={"metadata": {"path": str(scratch)}}
    ).execute()
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    images = [o for o in outputs if "image/png" in o.get("data", {})]
    assert len(images) == 2, "the joints plot and the map with the path"
    text = "\n".join(str(o.get("text", "")) + str(o.get("data", {}).get("text/plain", "")) for o in outputs)
    assert "owned by you" in text and "poses planned; stopped at" in text, text[-2000:]
    from user_peer import notebook

    widgets = [o for o in outputs if "application/vnd.jupyter.widget-view+json" in o.get("data", {})]
    if notebook.available():
        assert widgets, "the inline Rerun view was not created"
    else:
        assert not widgets and "pip install 'robofabric[notebook]'" in text
