"""The peers' memory over a soak, from a ``robofabric bench soak --out RUN.json`` document.

``python -m robofabric.soak.plot RUN.json OUT.svg``: one line per peer role (every incarnation of a role in
one line: a restart shows as a step down), resident memory against the minute of the run, with the faults'
count and the violations in the title. Needs matplotlib (the ``test`` or ``notebook`` extra), imported only here.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

__all__ = ["plot"]


def plot(doc: dict, out: Path | str) -> None:
    """Write the figure for ``doc`` to ``out`` (its suffix picks the format)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as e:
        from fabric.cli_common import UserError

        raise UserError(f"the soak's plot needs matplotlib (pip install -e '.[test]'): {e}") from None
    fig, ax = plt.subplots(figsize=(9, 4.5))
    for name, pts in sorted(doc["memory_mb"].items()):
        if pts:
            ax.plot([p[0] for p in pts], [p[1] for p in pts], label=name, linewidth=1.2)
    faults = sum(doc["faults"].values())
    ax.set_title(
        f"robofabric bench soak --minutes {doc['minutes']:g}: {faults} faults of {len(doc['faults'])} kinds, "
        f"{len(doc['violations'])} violations",
        fontsize=10,
    )
    ax.set_xlabel("minute of the run")
    ax.set_ylabel("resident memory (MB)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, ncol=2, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        raise SystemExit("usage: python -m robofabric.soak.plot RUN.json OUT.svg")
    plot(json.loads(Path(sys.argv[1]).read_text()), sys.argv[2])
