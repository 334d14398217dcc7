"""The maps a navigation service holds, their costmaps and their files (no session here).

Maps are kept by name with a version that each replacement bumps, so a costmap (the map inflated by a robot
radius, the costly part of a plan) is built once per (map version, radius, threshold) and reused; the cache is
bounded because requests may vary the radius. Files are read and written only inside ``maps_dir``: a map name
comes from the wire and must not reach anywhere else on the compute machine's disk.

Maps users build in their own names are counted by user: at most :data:`MAX_MAPS_PER_USER` each and
:data:`MAX_USER_MAPS` in all, so a student naming maps in a loop cannot grow the compute peer (1,400 builds under
new names took one from 142 to 528 MB, for good). Past a cap a new name is refused with the reason; rebuilding a
map she has is always allowed. The staff's maps (built, loaded or set on the forms without ``by/``) are not
counted: they are few and theirs to manage.
"""

from __future__ import annotations

import threading
from pathlib import Path as FsPath

from fabric.interfaces import OccupancyGrid

from .costmap import Costmap, build_costmap
from .errors import NavigationError
from .grid import is_empty
from .mapio import load_map, save_map

__all__ = ["COSTMAP_CACHE", "MAX_MAPS_PER_USER", "MAX_USER_MAPS", "MapLimit", "MapStore"]

COSTMAP_CACHE = 8
"""Costmaps kept at once (oldest dropped first)."""
MAX_MAPS_PER_USER = 4
"""Maps one user may hold at once (her builds under distinct names)."""
MAX_USER_MAPS = 64
"""Maps all users together may hold at once: with the scans' grid at its default 400 x 400 cells, about
64 x 160 KB kept here and as much in the latched publishers' caches."""


class MapLimit(NavigationError):
    """A user's new map was refused: she, or the users together, hold as many maps as allowed."""


class MapStore:
    """Maps by name, their costmaps, and the maps folder (None: saving and loading are disabled)."""

    def __init__(
        self,
        maps_dir: str | FsPath | None = None,
        *,
        per_user: int = MAX_MAPS_PER_USER,
        users_total: int = MAX_USER_MAPS,
    ) -> None:
        self.maps_dir = FsPath(maps_dir) if maps_dir is not None else None
        self.maps: dict[str, OccupancyGrid] = {}
        self.per_user = per_user
        self.users_total = users_total
        self._owners: dict[str, str] = {}  # map name -> the user who built it in her name (staff maps: absent)
        self._versions: dict[str, int] = {}
        self._costmaps: dict[tuple, Costmap] = {}
        self._lock = threading.Lock()

    def get(self, name: str) -> OccupancyGrid | None:
        with self._lock:
            return self.maps.get(name)

    def put(self, name: str, grid: OccupancyGrid, *, user: str = "") -> None:
        """Keep ``grid`` as map ``name``; the costmaps of its previous version are dropped.

        ``user``: the map is that user's (built in her name), counted against the caps; :class:`MapLimit`
        when it is a new name past one of them, and nothing is kept."""
        with self._lock:
            if user and name not in self.maps:
                self._admit(name, user)
            if user:
                self._owners[name] = user
            self.maps[name] = grid
            self._versions[name] = self._versions.get(name, 0) + 1
            self._drop_costmaps(name)

    def drop(self, name: str) -> None:
        """Forget map ``name`` and its costmaps."""
        with self._lock:
            self.maps.pop(name, None)
            self._owners.pop(name, None)
            self._drop_costmaps(name)

    def user_maps(self, user: str | None = None) -> list[str]:
        """The names of the maps ``user`` holds (None: every user's), sorted."""
        with self._lock:
            return sorted(n for n, u in self._owners.items() if user is None or u == user)

    def _admit(self, name: str, user: str) -> None:
        """Under the lock: refuse a new map of ``user`` past a cap."""
        mine = sorted(n for n, u in self._owners.items() if u == user)
        if len(mine) >= self.per_user:
            raise MapLimit(
                f"{user} holds {len(mine)} maps, the most one user may ({', '.join(mine)}): "
                f"build one of them again rather than a new name {name!r}"
            )
        if len(self._owners) >= self.users_total:
            raise MapLimit(
                f"the users hold {len(self._owners)} maps, the most this compute peer keeps: "
                f"build one of yours again, or ask an instructor"
            )

    def costmaps_cached(self) -> int:
        """How many inflated maps are cached (at most ``COSTMAP_CACHE``)."""
        with self._lock:
            return len(self._costmaps)

    def _drop_costmaps(self, name: str) -> None:
        self._costmaps = {k: v for k, v in self._costmaps.items() if k[0] != name}

    def costmap(self, name: str, robot_radius: float, *, threshold: int, unknown_is_occupied: bool) -> Costmap:
        """Map ``name`` inflated by ``robot_radius`` (cached per map version); NavigationError without a usable map."""
        with self._lock:
            grid = self.maps.get(name)
            version = self._versions.get(name, 0)
        if grid is None:
            raise NavigationError(
                f"no map named {name!r}: drive with mapping on and build it (map service, action 'build'), or load/set one"
            )
        if is_empty(grid):
            raise NavigationError(f"map {name!r} is empty: no cell is known to be free")
        ck = (name, version, robot_radius, threshold, unknown_is_occupied)
        with self._lock:
            cm = self._costmaps.get(ck)
        if cm is None:
            cm = build_costmap(grid, robot_radius, threshold=threshold, unknown_is_occupied=unknown_is_occupied)
            with self._lock:
                while len(self._costmaps) >= COSTMAP_CACHE:
                    self._costmaps.pop(next(iter(self._costmaps)))
                self._costmaps[ck] = cm
        return cm

    # ------------------------------------------------------------------ files

    def file(self, name: str) -> FsPath:
        """The path of map file ``name`` inside the maps folder; NavigationError for anything else."""
        if self.maps_dir is None:
            raise NavigationError("this compute peer has no maps folder: saving and loading are disabled")
        if not name or "/" in name or "\\" in name or name.startswith("."):
            raise NavigationError(f"map file name {name!r} must be a plain file name inside the maps folder")
        return self.maps_dir / name

    def save(self, name: str, file: str) -> FsPath:
        """Write map ``name`` to ``file`` in the maps folder (format by extension); returns the path written."""
        stored = self.get(name)
        if stored is None:
            raise NavigationError(f"no map named {name!r} to save (build, load or set one first)")
        return save_map(stored, self.file(file))

    def read(self, file: str) -> tuple[OccupancyGrid, FsPath]:
        """Read ``file`` from the maps folder (not kept: the caller stamps and stores it)."""
        path = self.file(file)
        return load_map(path), path
