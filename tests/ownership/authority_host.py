"""A small authority host for the multi-process tests: an Authority in its own process.

Motion is scripted by a file (``moving`` / ``still``) polled every 10 ms. Commands on
``rf/{world}/robot/arm/cmd/*`` pass the gate; a rejection is published as an event
``rf/{world}/event/reject/arm`` and an admitted one as ``.../event/accept/arm``.
argv: WORLD PORT MOTION_FILE LEASE_S GRACE_S
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from fabric import keys
from fabric.interfaces import Command, Event
from fabric.session import shutdown_event
from robofabric.testing import client

from ownership import Authority


def main() -> None:
    world, port, motion_file, lease_s, grace_s = (
        sys.argv[1],
        int(sys.argv[2]),
        Path(sys.argv[3]),
        float(sys.argv[4]),
        float(sys.argv[5]),
    )
    stop = shutdown_event()
    with client(world, port, kind="sim", peer_id="host") as fab:
        auth = Authority(fab, {"arm": "exclusive", "ball": "scene"}, lease_s=lease_s, grace_s=grace_s).start()

        def on_cmd(key: str, cmd: Command) -> None:
            reason = auth.admit("arm", cmd)
            kind = "reject" if reason else "accept"
            fab.reports.emit(
                Event(kind=kind, reason=reason or "", object="arm", user=cmd.user, header=fab.header("ev")), kind, "arm"
            )

        fab.subscribe(keys.robot_cmd_all(world, "arm"), on_cmd, expected=Command)
        print("ready", flush=True)
        while not stop.is_set():
            try:
                auth.update_motion("arm", motion_file.read_text().strip() == "moving")
            except OSError:
                pass
            time.sleep(0.01)
        auth.close()


if __name__ == "__main__":
    main()
