"""One login's flood of asks, as fast as her client can send them (a child process of the flood tests and
``robofabric bench secure``'s flood row): ownership requests on her own key, or ``srv/state`` queries.

    python -m robofabric.bench.login_flood WORLD ZENOH_CONFIG LOGIN {request ROBOT | state} SECONDS

Queries go out without waiting for answers (zenoh's callbacks count them), so the rate is the client's
fastest, not one round trip's. Prints one JSON line: ``sent``, ``seconds``, and ``answers`` counted by kind:
the reply's outcome (``granted``, ``denied``...) or message type, ``rate_limited`` for a refusal of a spent
budget, ``refused`` for any other refusal, and ``no_reply`` for a query that timed out.
"""

from __future__ import annotations

import json
import sys
import threading
import time
from collections import Counter

import zenoh

from fabric import keys
from fabric.budget import RATE_LIMITED
from fabric.codec import decode, encode
from fabric.config import FabricConfig
from fabric.interfaces import OwnRequest
from fabric.session import Fabric

__all__ = ["flood", "answer_kind"]


def answer_kind(reply) -> str:
    """What one zenoh reply was: an outcome or a type, ``rate_limited``, ``refused`` or ``no_reply``."""
    try:
        if reply.ok is not None:
            msg = decode(reply.ok.payload.to_bytes())
            return str(getattr(msg, "outcome", type(msg).__name__))
        err = reply.err.payload.to_bytes()
        try:
            reason = decode(err).reason
        except Exception:
            return "no_reply" if err.decode(errors="replace") == "Timeout" else "refused"
        return RATE_LIMITED if reason.startswith(RATE_LIMITED) else "refused"
    except Exception:
        return "refused"


def flood(world: str, config_file: str, login: str, what: str, robot: str, seconds: float) -> dict:
    """Send ``what`` (``request`` for ``robot``, or ``state``) for ``seconds``; wait for the last answers."""
    answers: Counter[str] = Counter()
    lock = threading.Lock()
    done = threading.Semaphore(0)

    def on_reply(reply) -> None:
        kind = answer_kind(reply)
        with lock:
            answers[kind] += 1

    with Fabric(FabricConfig(world=world, config_file=config_file), kind="user", peer_id=login) as fab:
        if what == "request":
            key = keys.own_request(world, robot, login)
            payload = encode(OwnRequest("request", login, False, header=fab.header("own-req")))
        else:
            key, payload = keys.srv(world, "state"), None
        sent, t0 = 0, time.monotonic()
        while time.monotonic() - t0 < seconds:
            fab.session.get(key, zenoh.handlers.Callback(on_reply, done.release), payload=payload, timeout=3.0)
            sent += 1
        took = time.monotonic() - t0
        for _ in range(sent):  # every query ends (answered or timed out) within its 3 s
            if not done.acquire(timeout=10.0):
                break
    with lock:
        return {"sent": sent, "seconds": round(took, 3), "answers": dict(answers)}


if __name__ == "__main__":
    world, config_file, login, what, *rest = sys.argv[1:]
    robot = rest[0] if what == "request" else ""
    print(json.dumps(flood(world, config_file, login, what, robot, float(rest[-1]))), flush=True)
