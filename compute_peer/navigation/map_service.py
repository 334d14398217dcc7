"""The map service's actions (``srv/map/{name}``, :class:`MapRequest`): start/stop mapping, build, get, reset,
save/load, set, status.

A map that is built, loaded or set is stamped by this peer, kept in the :class:`MapStore` and published on
``rf/{world}/map/{name}`` (a latched key: late joiners get it). Refusals are :class:`NavigationError` with the
reason; the service turns them into error replies.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

from fabric import keys
from fabric.interfaces import empty_grid, MapReply, MapRequest, OccupancyGrid

from .errors import NavigationError
from .grid import check_grid
from .map_store import MapStore
from .scan_mapping import ScanMapping

if TYPE_CHECKING:
    from fabric.session import Fabric

__all__ = ["MapService"]


class MapService:
    """Map requests for one world: ``map_name`` is the map built from scans."""

    def __init__(self, fabric: "Fabric", store: MapStore, scans: ScanMapping, *, map_name: str = "map") -> None:
        self.fabric = fabric
        self.world = fabric.world
        self.store = store
        self.scans = scans
        self.map_name = map_name

    def publish(self, name: str, grid: OccupancyGrid) -> OccupancyGrid:
        """Keep ``grid`` as map ``name`` (stamped by this peer) and publish it; returns what was kept."""
        key = keys.map_key(self.world, name)
        grid = replace(grid, header=self.fabric.header(key))
        self.store.put(name, grid)
        self.fabric.publish(key, grid)
        return grid

    def build(self, name: str | None = None, threshold: float = 0.65) -> OccupancyGrid:
        """Threshold the accumulated scans into a binary map, keep it as ``name`` and publish it."""
        name = name or self.map_name
        grid = self.scans.grid(threshold=threshold)
        if grid is None:
            raise NavigationError("no scans accumulated yet: is mapping on and are the robots publishing scan and pose?")
        return self.publish(name, grid)

    def handle(self, req: MapRequest) -> MapReply:
        """Handle one map request (also usable in-process, without Zenoh)."""
        name = keys.validate_id(req.name, what="map name")
        grid = empty_grid()
        file = ""
        a = req.action
        if a == "start":
            self.scans.on = True
        elif a == "stop":
            self.scans.on = False
        elif a == "reset":
            self.scans.reset()
            self.store.drop(name)
        elif a == "build":
            grid = self.build(name, req.threshold)
        elif a == "get":
            grid = self._get(name)
        elif a == "save":
            file = self.store.save(name, req.file or f"{name}.yaml").name
        elif a == "load":
            loaded, path = self.store.read(req.file or f"{name}.yaml")
            grid = self.publish(name, loaded)
            file = path.name
        elif a == "set":
            if req.grid.cells.size == 0:
                raise NavigationError("action 'set' needs a grid with cells")
            check_grid(req.grid)
            grid = self.publish(name, req.grid)
        elif a != "status":
            raise NavigationError(f"unknown map action {a!r}")
        return MapReply(
            a, name, grid, self.scans.scans, int(self.scans.on), file, self.fabric.header(keys.srv(self.world, "map", name))
        )

    def _get(self, name: str) -> OccupancyGrid:
        """The stored map ``name``; for the scans' map before any build, the live probabilities."""
        stored = self.store.get(name)
        if stored is not None:
            return stored
        if name == self.map_name and self.scans.scans > 0:
            live = self.scans.grid(header=self.fabric.header(keys.map_key(self.world, name)))
            if live is not None:  # None only when a reset came in between
                return live
        raise NavigationError(f"no map named {name!r} (build, load or set one first)")
