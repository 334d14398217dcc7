"""``robofabric view`` against what any login may write on ownership keys and in the liveliness space:
garbage payloads are counted and skipped, a token that names no peer is ignored, names that look like markup or
carry escape sequences are logged as data; the viewer keeps drawing and logs no traceback."""

from __future__ import annotations

import logging
import threading

from fabric import keys
from fabric.interfaces import Header, OwnershipRecord
from robofabric.testing import client_config, wait_until
from user_peer.viewer import Viewer, ViewerOptions


def test_viewer_skips_garbage_and_bad_tokens_on_ownership_and_keeps_drawing(world, router, connect, tmp_path, caplog):
    caplog.set_level(logging.WARNING)
    viewer = Viewer(
        client_config(world, router[1]), ViewerOptions(save=tmp_path / "view.rrd", max_hz=0), peer_id="viewer-hostile"
    )
    stop = threading.Event()
    t = threading.Thread(target=viewer.run, args=(stop,), daemon=True)
    t.start()
    mallory = connect("tool", "mallory")
    wait_until(lambda: ("viewer", "viewer-hostile") in mallory.live_peers("viewer"), what="viewer token")
    tokens = [
        mallory.session.liveliness().declare_token(f"rf/{world}/peer/sim/with space"),
        mallory.session.liveliness().declare_token(f"rf/{world}/peer/sim/a/b/c"),
    ]
    try:
        i = 0

        def logged(n: int):
            def check() -> bool:
                nonlocal i
                i += 1
                mallory.publish(
                    keys.own(world, "arm1"),
                    OwnershipRecord("arm1", owner="[/x]\x1b[2J", epoch=i, queue=("[bold]q",), header=Header.now()),
                )
                return viewer.logger.counts["OwnershipRecord"] >= n

            return check

        # the viewer subscribes once it has asked for the world's description: a record drawn says it listens
        wait_until(
            logged(1),
            timeout=30,
            interval=0.1,
            what="the viewer drawing records",
            seen=lambda: dict(viewer.logger.counts),
        )
        mallory.session.put(keys.own(world, "arm1"), b"\x00not msgpack")
        mallory.session.put(keys.own(world, "arm1"), b"\x93\xa1x")
        mallory.session.put(f"rf/{world}/own/arm1/extra/chunks", b"\x00")
        wait_until(
            lambda: viewer.fab.counters["decode_errors"] >= 3,
            what="garbage counted",
            seen=lambda: dict(viewer.fab.counters),
        )
        drawn = viewer.logger.counts["OwnershipRecord"]
        wait_until(
            logged(drawn + 2),
            timeout=20,
            interval=0.1,
            what="records drawn after the garbage",
            seen=lambda: dict(viewer.logger.counts),
        )
        assert t.is_alive()
    finally:
        for tok in tokens:
            tok.undeclare()
        stop.set()
        t.join(10)
        viewer.close()
    assert not t.is_alive()
    tracebacks = [r for r in caplog.records if r.exc_info]
    assert not tracebacks, [r.getMessage() for r in tracebacks]
