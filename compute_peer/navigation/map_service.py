"""The map service's actions (``srv/map/{name}``, :class:`MapRequest`): start/stop mapping, build, get, reset,
save/load, set, status.

A map that is built, loaded or set is stamped by this peer, kept in the :class:`MapStore` and published on
``rf/{world}/map/{name}`` (a latched key: late joiners get it). Refusals are :class:`NavigationError` with the
reason; the service turns them into error replies.

A user asking in her own name (``srv/map/.../by/{user}``, ``user`` here) builds her own map: ``build`` of ``name``
keeps and publishes :func:`fabric.keys.user_map` (``{user}.{name}``), never the class's map, and within the
store's caps (:class:`MapLimit`). Every build's threshold is checked against :data:`BUILD_THRESHOLD`.
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

__all__ = ["BUILD_THRESHOLD", "MAX_MAP_NAME", "MapService"]

BUILD_THRESHOLD = (0.5, 0.99)
"""The thresholds a build takes (a cell is occupied when its probability is above it). Below 0.5 a cell seen free
about as often as occupied counts as an obstacle, and at 0.001 every cell ever seen does: a map no plan can cross."""
MAX_MAP_NAME = 64
"""The longest map name a user's build may make (her name, ``.``, the name she gave)."""


class MapService:
    """Map requests for one world: ``map_name`` is the map built from scans."""

    def __init__(self, fabric: "Fabric", store: MapStore, scans: ScanMapping, *, map_name: str = "map") -> None:
        self.fabric = fabric
        self.world = fabric.world
        self.store = store
        self.scans = scans
        self.map_name = map_name

    def publish(self, name: str, grid: OccupancyGrid, *, user: str = "") -> OccupancyGrid:
        """Keep ``grid`` as map ``name`` (stamped by this peer; ``user``'s, counted against the store's caps)
        and publish it; returns what was kept."""
        key = keys.map_key(self.world, name)
        grid = replace(grid, header=self.fabric.header(key))
        self.store.put(name, grid, user=user)
        self.fabric.publish(key, grid)
        return grid

    def build(self, name: str | None = None, threshold: float = 0.65, *, user: str = "") -> OccupancyGrid:
        """Threshold the accumulated scans into a binary map, keep it as ``name`` and publish it; with ``user``,
        as her own map (:func:`fabric.keys.user_map`). NavigationError for a threshold outside
        :data:`BUILD_THRESHOLD`, a name too long, or a new map past the caps."""
        name = self.built_name(name or self.map_name, user)
        lo, hi = BUILD_THRESHOLD
        if not lo <= threshold <= hi:
            raise NavigationError(
                f"threshold {threshold:g} is outside [{lo:g}, {hi:g}]: a cell is occupied when its probability "
                f"is above it, and below {lo:g} cells seen free count as obstacles (the default is 0.65)"
            )
        grid = self.scans.grid(threshold=threshold)
        if grid is None:
            raise NavigationError(
                "no scans accumulated yet: is mapping on and are the robots publishing scan and pose?"
            )
        return self.publish(name, grid, user=user)

    @staticmethod
    def built_name(name: str, user: str = "") -> str:
        """The map a build of ``name`` asked by ``user`` makes ('' for the staff: ``name`` itself)."""
        if not user:
            return name
        mine = keys.user_map(name, user)
        if len(mine) > MAX_MAP_NAME:
            raise NavigationError(f"map name {mine!r} is {len(mine)} characters long; at most {MAX_MAP_NAME}")
        return mine

    def handle(self, req: MapRequest, *, user: str = "") -> MapReply:
        """Handle one map request (also usable in-process, without Zenoh); ``user``: asked in her own name
        (a build then makes her map: the reply names it)."""
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
            name = self.built_name(name, user)
            grid = self.build(name, req.threshold, user=user)
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
            a,
            name,
            grid,
            self.scans.scans,
            int(self.scans.on),
            file,
            self.fabric.header(keys.srv(self.world, "map", name)),
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
