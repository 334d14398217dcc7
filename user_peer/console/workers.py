"""The console's threads for blocking calls, one pool per kind of work.

NiceGUI's ``run.io_bound`` shares one pool of ``min(32, cores + 4)`` threads (six on a 2-core machine) among
every page of the server. A class's blocking calls (plans of up to 20 s, map builds, IK, the first look at the
world) filled it, and a student's login then waited behind them: once in CI a login was not answered in 60 s.
Logins, a page's first handles and the teacher's reads get threads of their own (:data:`LOGINS`); a page's
buttons share :data:`CALLS`; the twists, a put each, :data:`TWISTS`. Idle threads cost nothing, so the pools are
sized for a class of 32, each page one call in flight and a few logins at once.
"""

from __future__ import annotations

import asyncio
import functools
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Callable, TypeVar

__all__ = ["CALLS", "LOGINS", "TWISTS", "off_loop"]

R = TypeVar("R")

LOGINS = ThreadPoolExecutor(max_workers=8, thread_name_prefix="console-login")
"""Logins, a page's first look at its world, the teacher's reads: a student joining never waits behind a plan."""
CALLS = ThreadPoolExecutor(max_workers=48, thread_name_prefix="console-call")
"""A page's buttons (request, plan, build map, IK, stop...): a call waits on the network, not on a core."""
TWISTS = ThreadPoolExecutor(max_workers=4, thread_name_prefix="console-twist")
"""The twists: a key never waits behind a login, a plan or a map build. A twist is a put: four serve a class."""


async def off_loop(pool: ThreadPoolExecutor, fn: Callable[..., R], *args: Any, **kw: Any) -> R:
    """``fn(*args, **kw)`` on a thread of ``pool``, awaited from the page's event loop."""
    return await asyncio.get_running_loop().run_in_executor(pool, functools.partial(fn, *args, **kw))
