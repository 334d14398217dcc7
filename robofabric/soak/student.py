"""One student of the soak's class, a process on a host of her own: ``python -m robofabric.soak.student``.

She owns her arm (``arm{i}``) and moves it between two poses of her own, and now and then gives it up for a
moment (whoever is queued gets it), or queues for her neighbour's arm, moves it a little and gives it
back. Every call may fail under the nemesis (a refusal, a timeout, the world gone for a while): she counts
it and carries on, until SIGTERM. Her seed makes her choices repeatable; the faults make the timing not.

Her targets keep joint 1 between 0.3 and 0.7 rad, so a robot reset to its zero pose, or moved to a pose no
student asks for, shows in the joints at once (the checker's ``reset`` and ``applied`` invariants).
"""

from __future__ import annotations

import random
import signal
import sys
import time

__all__ = ["targets", "main"]

SPEED = 0.3
"""The speed scale of every move: at most about 0.8 rad/s on a Meca500 joint (the checker's speed bound is 1 rad/s)."""


def targets(index: int) -> tuple[list[float], list[float]]:
    """Student ``index``'s two poses (rad, a Meca500's six joints)."""
    k = 0.02 * (index % 8)
    return ([0.7 - k, 0.3, -0.3, 0.0, 0.5, 0.1 + k], [0.35 + k, 0.1, -0.1, 0.2, 0.2, -0.2 - k])


def _own(robot, wait_s: float) -> bool:
    if robot.is_owner:
        return True
    robot.request(wait=True, timeout=wait_s)
    return True


def main(world: str, endpoint: str, index: int, arms: int, seed: int) -> None:
    import numpy as np

    from user_peer.api import connect

    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    rng = random.Random(seed * 1000 + index)
    mine, theirs = f"arm{index}", f"arm{(index + 1) % arms}"
    a, b = targets(index)
    counts = {"moves": 0, "failed": 0, "released": 0, "borrowed": 0}
    w = None
    while not stop:
        try:
            if w is None:
                w = connect(world, endpoint, user=f"s{index:02d}", timeout=10.0, join_timeout=120.0)
                print(f"student {index}: joined", flush=True)
            arm = w.robot(mine)
            _own(arm, 30.0)
            arm.move_joints(
                np.array(a if counts["moves"] % 2 else b), wait=True, tol=5e-3, timeout=20.0, speed_scale=SPEED
            )
            counts["moves"] += 1
            roll = rng.random()
            if roll < 0.12:
                arm.release()
                counts["released"] += 1
                time.sleep(rng.uniform(0.3, 2.0))
            elif roll < 0.22 and theirs != mine:
                other = w.robot(theirs)
                _own(other, 15.0)
                counts["borrowed"] += 1
                for q in (a, b):
                    other.move_joints(np.array(q), wait=True, tol=5e-3, timeout=20.0, speed_scale=SPEED)
                other.release()
            else:
                time.sleep(rng.uniform(0.0, 1.0))
        except Exception as exc:  # the nemesis at work: counted, and she goes on
            counts["failed"] += 1
            if counts["failed"] % 20 == 1:
                print(f"student {index}: {type(exc).__name__}: {str(exc)[:200]}", flush=True)
            time.sleep(rng.uniform(0.2, 1.0))
    print(f"student {index}: {counts}", flush=True)
    if w is not None:
        try:
            w.close()
        except Exception:
            pass


if __name__ == "__main__":
    if len(sys.argv) != 6:
        raise SystemExit("usage: python -m robofabric.soak.student WORLD ENDPOINT INDEX ARMS SEED")
    main(sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5]))
