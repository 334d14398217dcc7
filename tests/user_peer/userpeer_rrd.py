"""Read an .rrd back with Rerun's own loader: rows per entity path."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import rerun.chunk as rrc


def rows_per_entity(path: Path) -> Counter[str]:
    rows: Counter[str] = Counter()
    for chunk in rrc.RrdReader(str(path)).stream():
        rows[chunk.entity_path] += chunk.num_rows
    return rows


def entities_with_data(path: Path, prefix: str) -> dict[str, int]:
    return {e: n for e, n in rows_per_entity(path).items() if e.startswith(prefix) and n > 0}
