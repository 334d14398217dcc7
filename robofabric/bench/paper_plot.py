"""MB per minute against rate, from a ``robofabric bench paper --json`` document, beside the paper's figures.

``python -m robofabric.bench.paper_plot RUN.json OUT.svg`` (or ``bench paper --plot OUT.svg``): one line per
transport and payload (the average, whiskers from the per-window min to max), and the paper's Firebase points
(Tables 2-3). Log-log: the rates span 10-600 Hz and the payloads 180-4,100 bytes. Needs matplotlib (the
``test`` or ``notebook`` extra), imported only here.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

__all__ = ["plot"]

_STYLE = {"zenoh": "-", "mqtt": "--"}
_MARK = {"paper-135": "o", "rf-240": "s", "arm-joints": "^"}


def plot(doc: dict, out: Path | str) -> None:
    """Write the figure for ``doc`` (the ``--json`` document) to ``out`` (its suffix picks the format)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as e:
        from fabric.cli_common import UserError

        raise UserError(f"--plot needs matplotlib (pip install 'robofabric[notebook]'): {e}") from None
    fig, ax = plt.subplots(figsize=(7.5, 5))
    series: dict[tuple[str, str], list[dict]] = {}
    for r in doc["data_usage"]:
        series.setdefault((r["transport"], r["payload"]), []).append(r)
    for (transport, payload), rows in series.items():
        rows = sorted(rows, key=lambda r: r["rate_hz"])
        x = [r["rate_hz"] for r in rows]
        y = [r["mb_per_min_avg"] for r in rows]
        err = [
            [r["mb_per_min_avg"] - r["mb_per_min_min"] for r in rows],
            [r["mb_per_min_max"] - r["mb_per_min_avg"] for r in rows],
        ]
        ax.errorbar(
            x,
            y,
            yerr=err,
            linestyle=_STYLE.get(transport, ":"),
            marker=_MARK.get(payload, "x"),
            capsize=2,
            label=f"{transport}, {payload}",
        )
    paper = doc["paper"]["data_usage"]
    ax.plot(
        [p["rate_hz"] for p in paper],
        [p["mb_per_min_avg"] for p in paper],
        "k*",
        markersize=10,
        label="paper, Firebase REST (Tables 2-3)",
    )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("rate (Hz)")
    ax.set_ylabel("MB per minute on the publisher's link (avg; min-max)")
    ax.set_title(f"bench paper, {doc.get('duration_s', '?')} s per rate")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: python -m robofabric.bench.paper_plot RUN.json OUT.svg")
    plot(json.loads(Path(sys.argv[1]).read_text()), sys.argv[2])
