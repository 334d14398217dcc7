"""A multi-host lab on one Linux machine: network namespaces joined by a bridge, real processes in them.

Used by the ``lab`` tests (``tests/lab/``) and by hand (``robofabric lab up FILE.toml``); see docs/lan.md.

The names below load on first use (PEP 562): ``robofabric`` imports :mod:`robofabric.lab.cli` at every start
(``--help`` included), which must not pay for the lab itself.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from robofabric.lab.lab import DEFAULT_SUBNET, Host, Lab, LabProcess, RemoteError, RemotePython, faketime_library
    from robofabric.lab.netns import LabError, namespaces_available, netns_list, sweep_stale

_HOME = {
    **dict.fromkeys(
        ("DEFAULT_SUBNET", "Host", "Lab", "LabProcess", "RemoteError", "RemotePython", "faketime_library"),
        "robofabric.lab.lab",
    ),
    **dict.fromkeys(("LabError", "namespaces_available", "netns_list", "sweep_stale"), "robofabric.lab.netns"),
}
"""Each public name and the module that defines it."""

__all__ = sorted(_HOME)


def __getattr__(name: str) -> Any:
    """Load a public name from its module on first use, and keep it."""
    home = _HOME.get(name)
    if home is None:
        raise AttributeError(f"module 'robofabric.lab' has no attribute {name!r}")
    value = getattr(import_module(home), name)
    globals()[name] = value
    return value
