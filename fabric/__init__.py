"""The ground floor: what every peer needs at run time, and nothing else.

A sim, a compute peer, a user's script and the tools above them all stand on
this package: the session (:class:`Fabric`) and its configuration, the key
layout (:mod:`fabric.keys`), the messages (:mod:`fabric.interfaces`) and their
codec, limits and fixed-rate loops, the authority stamp and fences, the command
gate, and the recorder library (:mod:`fabric.recording`). The tools (CLI,
launch, lab, secure init, replay, benchmarks, the helpers tests share) live one
floor above the peers, in :mod:`robofabric` (docs/architecture.md, "The house").

The names below are the public API. They load on first use (PEP 562): a module
that needs only :mod:`fabric.keys` does not pay for zenoh, numpy and the
codec. Submodules import as usual (``from fabric import
keys``).
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from fabric.codec import DecodeError, decode, encode, load_plugins, register, registered
    from fabric.config import ConfigError, FabricConfig
    from fabric.exit import at_exit
    from fabric.gate import CommandGate, OpenGate
    from fabric.rate import Clock, MonotonicClock, RateLoop
    from fabric.recording import Recorder
    from fabric.session import Fabric, shutdown_event

_HOME = {
    "Fabric": "fabric.session",
    "shutdown_event": "fabric.session",
    "FabricConfig": "fabric.config",
    "ConfigError": "fabric.config",
    "encode": "fabric.codec",
    "decode": "fabric.codec",
    "DecodeError": "fabric.codec",
    "register": "fabric.codec",
    "registered": "fabric.codec",
    "load_plugins": "fabric.codec",
    "RateLoop": "fabric.rate",
    "Clock": "fabric.rate",
    "MonotonicClock": "fabric.rate",
    "at_exit": "fabric.exit",
    "CommandGate": "fabric.gate",
    "OpenGate": "fabric.gate",
    "Recorder": "fabric.recording",
}
"""Each public name and the module that defines it."""

__all__ = sorted(_HOME)


def __getattr__(name: str) -> Any:
    """Load a public name from its module on first use, and keep it (the next lookup is a plain attribute)."""
    home = _HOME.get(name)
    if home is None:
        raise AttributeError(f"module 'fabric' has no attribute {name!r}")
    value = getattr(import_module(home), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
