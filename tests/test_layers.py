"""Who may import whom: the import-linter contracts of pyproject.toml hold on the code, and they do bite.

``test_contracts_hold`` runs ``lint-imports`` on the project itself. The other tests run the same
contracts on a small tree of empty packages named like ours, with one import added, so a contract that
could never break (a typo in a module name, a wildcard that matches nothing) fails here.
"""

from __future__ import annotations

import logging
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LINT = Path(sys.executable).with_name("lint-imports")


def _run(
    config: Path, cwd: Path, extra_path: Path | None = None, contract: str | None = None
) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    if extra_path is not None:
        env["PYTHONPATH"] = str(extra_path)
    only = ["--contract", contract] if contract else []
    return subprocess.run(
        [str(LINT), "--config", str(config), "--no-cache", *only],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_contracts_hold(monkeypatch, capsys):
    """``lint-imports`` on the project, in this process (no child process: it stays in the fast suite)."""
    from importlinter.cli import lint_imports

    monkeypatch.chdir(ROOT)
    # import-linter configures logging with dictConfig, which disables every logger that exists: put them
    # back, or every later test in this process that reads the fabric's log lines (caplog) hears nothing
    manager = logging.root.manager
    disabled = {name: lg.disabled for name, lg in manager.loggerDict.items() if isinstance(lg, logging.Logger)}
    try:
        code = lint_imports(config_filename=str(ROOT / "pyproject.toml"), no_cache=True)
    finally:
        for name, lg in list(manager.loggerDict.items()):
            if isinstance(lg, logging.Logger):
                lg.disabled = disabled.get(name, lg.disabled)
    out = capsys.readouterr()
    assert code == 0, out.out + out.err
    assert "0 broken" in out.out
    for contract in (
        "Layers",
        "fabric.interfaces imports nothing",
        "fabric.codec and fabric.limits",
        "fabric, the ground floor",
        "No peer, nor ownership or robots, imports robofabric's tools",
        "The sim's pure decision cores",
        "The sim's rooms",
        "The user side's rooms",
        "robofabric's tool rooms",
    ):
        assert contract in out.out, out.out


def _importlinter_section() -> str:
    """The ``[tool.importlinter]`` tables of pyproject.toml, verbatim."""
    lines = (ROOT / "pyproject.toml").read_text().splitlines()
    out: list[str] = []
    inside = False
    for line in lines:
        if line.startswith("["):
            inside = line.strip("[] ").startswith("tool.importlinter")
        if inside:
            out.append(line)
    assert out, "pyproject.toml has no [tool.importlinter] section"
    return "\n".join(out) + "\n"


MODULES = [
    "robofabric/__init__.py",
    "robofabric/launch.py",
    "robofabric/bench/__init__.py",
    "robofabric/soak/__init__.py",
    "robofabric/lab/__init__.py",
    "sim_peer/__init__.py",
    "sim_peer/cli.py",
    "sim_peer/robot.py",
    "sim_peer/controllers.py",
    "sim_peer/sensors.py",
    "sim_peer/bumper.py",
    "sim_peer/physics/__init__.py",
    "sim_peer/physics/world.py",
    "sim_peer/physics/placement.py",
    "sim_peer/physics/robot_kinds.py",
    "sim_peer/serving/__init__.py",
    "sim_peer/serving/peer.py",
    "sim_peer/replica/__init__.py",
    "sim_peer/replica/roles.py",
    "sim_peer/replica/replica_host.py",
    "sim_peer/replica/election.py",
    "sim_peer/replica/hearing_rule.py",
    "sim_peer/replica/deaf_rule.py",
    "sim_peer/replica/freeze_rule.py",
    "sim_peer/replica/adoption_rule.py",
    "sim_peer/shards/__init__.py",
    "sim_peer/shards/move_rule.py",
    "sim_peer/shards/directory.py",
    "sim_peer/shards/mirroring.py",
    "compute_peer/__init__.py",
    "compute_peer/service.py",
    "user_peer/__init__.py",
    "user_peer/api.py",
    "user_peer/cli.py",
    "user_peer/console/__init__.py",
    "user_peer/console/page.py",
    "user_peer/ros2/__init__.py",
    "user_peer/ros2/cli.py",
    "user_peer/openfmt/__init__.py",
    "user_peer/drawing/__init__.py",
    "ownership/__init__.py",
    "ownership/client.py",
    "robots/__init__.py",
    "fabric/__init__.py",
    "fabric/limits.py",
    "fabric/codec/__init__.py",
    "fabric/codec/fields.py",
    "fabric/codec/registry.py",
    "fabric/codec/wire.py",
    "fabric/session.py",
    "fabric/rpc.py",
    "fabric/publishers.py",
    "fabric/fence_watch.py",
    "fabric/recording/__init__.py",
    "fabric/keys.py",
    "fabric/interfaces/__init__.py",
    "fabric/interfaces/std.py",
]
"""A skeleton of the project's packages; every module imports what the real one may import."""

ALLOWED = {
    "fabric/codec/__init__.py": "import fabric.codec.fields\nimport fabric.codec.registry\nimport fabric.codec.wire\n",
    "fabric/codec/fields.py": "import fabric.codec.wire\nimport fabric.limits\n",
    "fabric/codec/wire.py": "import fabric.codec.registry\nimport fabric.limits\n",
    "fabric/codec/registry.py": "def ensure_core():\n    import fabric.interfaces\n",
    "fabric/interfaces/std.py": "from fabric.codec import encode\nimport fabric.limits\n",
    "fabric/session.py": "import fabric.interfaces\nimport fabric.keys\n",
    "ownership/client.py": "import fabric.session\nimport fabric.interfaces\n",
    "sim_peer/serving/peer.py": "import ownership.client\nimport robots\nimport fabric.interfaces\nimport zenoh\n"
    "import sim_peer.physics.world\nimport sim_peer.shards.mirroring\n",
    "sim_peer/cli.py": "def main():\n    import sim_peer.replica.replica_host\n    import sim_peer.serving.peer\n",
    "sim_peer/replica/replica_host.py": "import sim_peer.shards.directory\nimport sim_peer.serving.peer\nimport sim_peer.replica.roles\n",
    "sim_peer/shards/directory.py": "from typing import TYPE_CHECKING\nimport sim_peer.replica.election\n"
    "if TYPE_CHECKING:\n    import sim_peer.replica.replica_host\n",
    "sim_peer/shards/mirroring.py": "import sim_peer.physics.world\nimport fabric.keys\n",
    "sim_peer/physics/robot_kinds.py": "import sim_peer.bumper\nimport sim_peer.controllers\nimport sim_peer.sensors\n",
    "sim_peer/bumper.py": "from typing import TYPE_CHECKING\nimport sim_peer.robot\nimport sim_peer.sensors\n"
    "if TYPE_CHECKING:\n    import sim_peer.physics.robot_kinds\n",
    "sim_peer/sensors.py": "import sim_peer.robot\n",
    "user_peer/cli.py": "import user_peer.openfmt\ndef register(app):\n    from user_peer.console import page\n",
    "user_peer/ros2/cli.py": "import user_peer.openfmt\ndef main():\n    from user_peer.cli import open_world\n",
    "user_peer/openfmt/__init__.py": "import user_peer.drawing\n",
    "user_peer/console/page.py": "import user_peer.api\n",
    "robofabric/bench/__init__.py": "import robofabric.soak\nimport robofabric.lab\nimport user_peer.console\n",
    "robofabric/soak/__init__.py": "import robofabric.lab\n",
    "sim_peer/replica/roles.py": "import sim_peer.replica.election\nimport sim_peer.replica.hearing_rule\nimport fabric.session\n",
    "sim_peer/replica/deaf_rule.py": "import sim_peer.replica.hearing_rule\n",
    "compute_peer/service.py": "import robots\nimport fabric.interfaces.std\n",
    "user_peer/api.py": "import ownership.client\nimport fabric.session\n",
    "robofabric/__init__.py": "import sim_peer.serving.peer\nimport user_peer.api\n",
    "robofabric/launch.py": "import fabric.session\nimport fabric.keys\n",
    "sim_peer/physics/world.py": "import sim_peer.physics.placement\nimport sim_peer.robot\nimport fabric.interfaces\n",
    "sim_peer/physics/placement.py": "import fabric.keys\n",
    "sim_peer/robot.py": "import sim_peer.controllers\nimport fabric.interfaces\n",  # sensors import the robot, not back
    "fabric/keys.py": "def valid(expr):\n    import zenoh\n",
}


def _skeleton(tmp_path: Path, bad: tuple[str, str] | None) -> Path:
    """The skeleton under ``tmp_path/src``, with ``bad`` = (module, line) appended (a module not in MODULES is
    added with that line)."""
    src = tmp_path / "src"
    for rel in MODULES + ([bad[0]] if bad is not None and bad[0] not in MODULES else []):
        f = src / rel
        f.parent.mkdir(parents=True, exist_ok=True)
        text = ALLOWED.get(rel, "")
        if bad is not None and bad[0] == rel:
            text += bad[1]
        f.write_text(text)
    config = tmp_path / "importlinter.toml"
    config.write_text(_importlinter_section())
    return src


@pytest.mark.slow
def test_skeleton_without_bad_imports_keeps_every_contract(tmp_path):
    src = _skeleton(tmp_path, None)
    out = _run(tmp_path / "importlinter.toml", tmp_path, src)
    assert out.returncode == 0, out.stdout + out.stderr


@pytest.mark.slow
@pytest.mark.parametrize(
    "where, line, contract",
    [
        ("compute_peer/service.py", "import sim_peer.serving.peer\n", "layers"),  # a peer importing another peer
        ("user_peer/api.py", "from compute_peer import service\n", "layers"),
        ("sim_peer/serving/peer.py", "import user_peer\n", "layers"),
        ("ownership/client.py", "import sim_peer\n", "layers"),  # the library importing a peer
        ("fabric/session.py", "import user_peer.api\n", "layers"),  # the ground floor importing upwards
        ("robots/__init__.py", "import ownership\n", "layers"),
        ("fabric/interfaces/std.py", "import fabric.session\n", "interfaces"),
        ("fabric/interfaces/__init__.py", "from fabric import keys\n", "interfaces"),
        ("fabric/interfaces/std.py", "import robots\n", "interfaces"),
        ("fabric/codec/wire.py", "import fabric.session\n", "codec"),
        ("fabric/codec/fields.py", "import fabric.keys\n", "codec"),
        ("fabric/limits.py", "import fabric.keys\n", "codec"),
        ("fabric/session.py", "from robofabric import launch\n", "ground-floor"),  # the core leaning on a tool
        ("fabric/keys.py", "def later():\n    import robofabric.launch\n", "ground-floor"),  # even inside a function
        ("sim_peer/serving/peer.py", "import robofabric.launch\n", "tools"),  # a peer importing a tool
        ("user_peer/api.py", "from robofabric import launch\n", "tools"),
        ("ownership/client.py", "import robofabric\n", "tools"),
        ("robots/__init__.py", "import robofabric.launch\n", "tools"),
        ("sim_peer/replica/deaf_rule.py", "import zenoh\n", "pure-cores"),  # a pure core opening sessions
        ("sim_peer/replica/freeze_rule.py", "def later():\n    import fabric.session\n", "pure-cores"),
        (
            "sim_peer/replica/hearing_rule.py",
            "from sim_peer.replica import roles\n",
            "pure-cores",
        ),  # a core reaching into its shell
        ("sim_peer/replica/election.py", "import sim_peer.serving.peer\n", "pure-cores"),  # zenoh through the peer
        ("sim_peer/replica/adoption_rule.py", "from fabric import session\n", "pure-cores"),
        ("sim_peer/shards/move_rule.py", "import zenoh\n", "pure-cores"),
        ("sim_peer/physics/world.py", "import zenoh\n", "sim-physics"),  # the MuJoCo world opening sessions
        ("sim_peer/physics/placement.py", "from fabric import session\n", "sim-physics"),
        (
            "sim_peer/robot.py",
            "import sim_peer.serving.peer\n",
            "sim-physics",
        ),  # the plug-in surface leaning on the peer
        ("sim_peer/sensors.py", "import sim_peer.replica.roles\n", "sim-physics"),
        ("sim_peer/serving/peer.py", "import sim_peer.replica.roles\n", "sim-rooms"),  # serving leaning on the replica
        ("sim_peer/serving/peer.py", "from sim_peer.shards import directory\n", "sim-rooms"),  # shards past the mirrors
        ("sim_peer/shards/mirroring.py", "def later():\n    import sim_peer.cli\n", "sim-rooms"),  # a room on the CLI
        ("sim_peer/physics/placement.py", "import sim_peer.serving\n", "sim-rooms"),
        ("sim_peer/controllers.py", "import sim_peer.robot\n", "sim-rooms"),  # the plug-in surface's own order
        ("sim_peer/sensors.py", "import sim_peer.physics.placement\n", "sim-rooms"),  # the surface on the world
        ("sim_peer/stray.py", "import sim_peer.robot\n", "sim-rooms"),  # a module in no room (exhaustive)
        ("user_peer/console/page.py", "import user_peer.cli\n", "user-rooms"),  # the console on the CLI above it
        ("user_peer/console/page.py", "from user_peer import openfmt\n", "user-rooms"),  # independent rooms
        ("user_peer/openfmt/__init__.py", "def later():\n    import user_peer.console.page\n", "user-rooms"),
        ("user_peer/cli.py", "import user_peer.ros2.cli\n", "user-rooms"),  # the CLI on the bridge above it
        ("user_peer/drawing/__init__.py", "import user_peer.openfmt\n", "user-rooms"),
        ("robofabric/lab/__init__.py", "import robofabric.soak\n", "tool-rooms"),  # the lab on its user
        ("robofabric/soak/__init__.py", "from robofabric import bench\n", "tool-rooms"),
    ],
)
def test_a_bad_import_breaks_its_contract(tmp_path, where, line, contract):
    """``contract`` is the id of the contract that must catch ``line`` added to ``where``, run alone."""
    src = _skeleton(tmp_path, (where, line))
    out = _run(tmp_path / "importlinter.toml", tmp_path, src, contract=contract)
    assert out.returncode != 0, f"{where}: {line.strip()} was not caught by {contract!r}:\n{out.stdout}{out.stderr}"
    assert "BROKEN" in out.stdout and "1 broken" in out.stdout, out.stdout
