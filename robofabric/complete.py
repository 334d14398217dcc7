"""Shell completion of the values the CLI takes: keys of a live world, message types, export formats.

Each completer is a typer ``autocompletion=`` callback: ``(ctx, incomplete) -> list[str]``. They run
only while the shell asks for completions (``_ROBOFABRIC_COMPLETE=complete_bash ...``), so this
module imports nothing heavy at its top: zenoh, the codec and the exporters load inside the calls.
A completer never raises and never hangs: no router, a refusing router or a broken plugin gives [].

Keys come from one short look at the world (:func:`live_keys`): the key expressions its peers
subscribe to and serve (as each tells, :mod:`fabric.declared`), the peers' liveliness tokens, and the keys
that carry traffic within ``KEY_LOOK_S``; about a second in all when a router answers, ``connect``
giving up after ``CONNECT_TIMEOUT_MS`` when none does.
"""

from __future__ import annotations

import json
import threading
import time
from typing import Any

from user_peer.completion import complete_export_formats, complete_formats, matching

__all__ = [
    "live_keys",
    "complete_keys",
    "complete_keys_or_recordings",
    "complete_peers",
    "complete_types",
    "complete_formats",
    "complete_export_formats",
    "matching",
]

CONNECT_TIMEOUT_MS = 600
"""How long completion waits for a router before it offers nothing."""
KEY_LOOK_S = 0.3
"""How long completion listens to the world's traffic for keys."""
QUERY_TIMEOUT_S = 0.3
"""How long each admin-space and liveliness query waits for answers."""


def live_keys(
    world: str | None = None,
    connect: list[str] | None = None,
    profile: str | None = None,
    zenoh_config: Any = None,
    *,
    look_s: float = KEY_LOOK_S,
) -> list[str]:
    """The keys and key expressions live in ``world``, full (``rf/W/...``); [] when no router answers.

    Opens a bare zenoh session (no liveliness token of its own, so ``ps`` never shows it), asks the
    peers what they subscribe to and serve, the liveliness space for peers, and listens to the
    world's traffic for ``look_s`` s."""
    try:
        import zenoh

        from fabric import keys
        from fabric.cli_common import make_config
        from robofabric.declarations import read_declarations

        cfg = make_config(world, connect, None, profile, zenoh_config)
        conf = cfg.zenoh_config()
        conf.insert_json5("connect/timeout_ms", json.dumps({"client": CONNECT_TIMEOUT_MS, "peer": CONNECT_TIMEOUT_MS}))
        session = zenoh.open(conf)
    except Exception:
        return []
    found: set[str] = set()
    lock = threading.Lock()
    try:
        root = keys.world_root(cfg.world)

        def on_sample(sample: Any) -> None:
            with lock:
                found.add(str(sample.key_expr))

        sub = session.declare_subscriber(keys.world_all(cfg.world), on_sample)
        start = time.monotonic()
        try:
            decl = read_declarations(session, cfg.world, timeout=QUERY_TIMEOUT_S)
            found.update(decl.subscribers)
            found.update(decl.queryables)
        except Exception:
            pass
        try:
            for rep in session.liveliness().get(keys.peers_all(cfg.world), timeout=QUERY_TIMEOUT_S):
                if rep.ok is not None:
                    found.add(str(rep.ok.key_expr))
        except Exception:
            pass
        left = look_s - (time.monotonic() - start)
        if left > 0:
            time.sleep(left)
        sub.undeclare()
    except Exception:
        pass
    finally:
        try:
            session.close()
        except Exception:
            pass
    with lock:
        return sorted(k for k in found if k.startswith(root + "/") and k.isprintable() and " " not in k)


def _param(ctx: Any, name: str) -> Any:
    """A parameter's value as parsed so far, walking up to the parents' (root options)."""
    while ctx is not None:
        params = getattr(ctx, "params", None) or {}
        if params.get(name) is not None:
            return params[name]
        ctx = getattr(ctx, "parent", None)
    return None


def complete_keys(ctx: Any, incomplete: str) -> list[str]:
    """Keys of the live world named by the command line's ``--world``/``--connect`` (or the environment):
    world-relative (``robot/arm1/joints``) unless what was typed starts with ``rf/``."""
    try:
        from fabric.keys import world_root

        full = live_keys(
            _param(ctx, "world"), _param(ctx, "connect"), _param(ctx, "profile"), _param(ctx, "zenoh_config")
        )
        if not full:
            return []
        if incomplete.startswith("rf/"):
            return matching(full, incomplete)
        from fabric.cli_common import make_config

        root = world_root(make_config(_param(ctx, "world")).world) + "/"
        return matching((k[len(root) :] for k in full if k.startswith(root)), incomplete.lstrip("/"))
    except Exception:
        return []


def complete_peers(ctx: Any, incomplete: str) -> list[str]:
    """``ps -v PEER``: the ids of the live world's peers (from their liveliness tokens ``peer/KIND/ID``)."""
    try:
        from fabric.cli_common import make_config
        from fabric.keys import world_root

        prefix = world_root(make_config(_param(ctx, "world")).world) + "/peer/"
        full = live_keys(
            _param(ctx, "world"),
            _param(ctx, "connect"),
            _param(ctx, "profile"),
            _param(ctx, "zenoh_config"),
            look_s=0.0,
        )
        ids = [
            k[len(prefix) :].split("/", 1)[1] for k in full if k.startswith(prefix) and k[len(prefix) :].count("/") == 1
        ]
        return matching(ids, incomplete)
    except Exception:
        return []


def complete_keys_or_recordings(ctx: Any, incomplete: str) -> list[str]:
    """``info TARGET``: recordings (``*.mcap``) and folders here, then the live world's keys; what looks like a
    path (``./``, ``/``, ``~``, a dot) is completed as a path only."""
    try:
        import glob
        import os

        paths = [p + "/" if os.path.isdir(p) else p for p in glob.glob(os.path.expanduser(incomplete) + "*")]
        paths = [p for p in paths if p.endswith(("/", ".mcap"))]
        if incomplete.startswith(("/", ".", "~")) or "." in incomplete:
            return sorted(paths)
        return sorted(paths) + [k for k in complete_keys(ctx, incomplete) if k not in paths]
    except Exception:
        return []


def complete_types(incomplete: str) -> list[str]:
    """Message type names, plugins' included (``pub --type``, ``call --type``, ``interfaces TYPE``)."""
    try:
        from fabric.codec import load_plugins, registered

        load_plugins()
        return matching(registered(), incomplete)
    except Exception:
        return []
