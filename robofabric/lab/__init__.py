"""A multi-host lab on one Linux machine: network namespaces joined by a bridge, real processes in them.

Used by the ``lab`` tests (``tests/lab/``) and by hand (``robofabric lab up FILE.toml``); see docs/lan.md.
"""

from robofabric.lab.lab import DEFAULT_SUBNET, Host, Lab, LabProcess, RemoteError, RemotePython, faketime_library
from robofabric.lab.netns import LabError, namespaces_available, netns_list, sweep_stale

__all__ = [
    "DEFAULT_SUBNET", "Host", "Lab", "LabError", "LabProcess", "RemoteError", "RemotePython",
    "faketime_library", "namespaces_available", "netns_list", "sweep_stale",
]
