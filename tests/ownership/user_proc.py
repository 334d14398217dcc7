"""A user peer in its own process: requests OBJ (waiting if asked), prints each outcome, renews until killed.

argv: WORLD PORT USER OBJ [wait]
"""

from __future__ import annotations

import sys

from fabric.session import shutdown_event
from robofabric.testing import client

from ownership import OwnershipClient


def main() -> None:
    world, port, user, obj = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4]
    wait = len(sys.argv) > 5 and sys.argv[5] == "wait"
    stop = shutdown_event()
    with client(world, port, kind="user", peer_id=user) as fab:
        own = OwnershipClient(fab, user, renew_s=0.1).start()
        print("outcome", own.request(obj, wait=wait), flush=True)
        stop.wait()
        own.close()


if __name__ == "__main__":
    main()
