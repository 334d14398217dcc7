"""robofabric's own name on the import path: the version and the console script.

The fabric's code lives in the top-level packages ``fabric``, ``robots``,
``ownership``, ``sim_peer``, ``compute_peer`` and ``user_peer`` (see
docs/architecture.md). Three of those names are taken on PyPI by unrelated
projects, and the SSH library *Fabric* (``pip install fabric``) writes its files
into the same ``fabric/`` directory as ours. This package has the distribution's
own name, so the console script starts here and can say so before importing
``fabric`` (:mod:`robofabric.clash`).
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("robofabric")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0+unknown"

__all__ = ["__version__"]
