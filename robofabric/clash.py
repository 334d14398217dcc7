"""Is our top-level ``fabric`` package still ours? (the SSH library Fabric installs into the same name)

``pip install fabric`` installs the SSH library; its files land in the same
``site-packages/fabric/`` directory as robofabric's and replace
``fabric/__init__.py`` and ``fabric/config.py`` among others, after which
``robofabric`` breaks in confusing ways. The check reads installed distributions'
metadata only (no import of ``fabric``), so it works even when ``fabric`` no
longer imports.
"""

from __future__ import annotations

from importlib.metadata import distributions
from typing import Iterable

__all__ = ["SSH_FABRIC", "fabric_clash"]

SSH_FABRIC = "fabric"
"""The PyPI distribution name of the SSH library Fabric (ours is ``robofabric``)."""


def fabric_clash(path: Iterable[str] | None = None) -> str | None:
    """A warning when a distribution named ``fabric`` is installed beside robofabric, else None.

    ``path`` is the list of directories to look in (default: ``sys.path``), so a test can point
    it at a directory holding a real ``fabric-X.dist-info``.
    """
    kw = {} if path is None else {"path": list(path)}
    # found by name (the metadata directory's, normalised): reading every distribution's METADATA
    # costs ~70 ms of CPU, a quarter of `robofabric --help`
    for dist in distributions(name=SSH_FABRIC, **kw):
        name = (dist.metadata.get("Name") or "").strip().lower().replace("_", "-")
        if name != SSH_FABRIC:
            continue
        ver = dist.metadata.get("Version") or "?"
        return (
            f"warning: the package 'fabric' {ver} (the SSH library Fabric) is installed in this environment; "
            "it shares the top-level name 'fabric' with robofabric and replaces its files, so robofabric may fail. "
            "Use a separate virtual environment for robofabric, or `pip uninstall fabric` and then "
            "`pip install --force-reinstall robofabric`."
        )
    return None
