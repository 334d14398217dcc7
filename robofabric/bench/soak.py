"""``robofabric bench soak``: a class in the lab for M minutes under a seeded nemesis, then the checker.

See :mod:`robofabric.soak.run` for the class and :mod:`robofabric.soak.checker` for what is checked. The
run prints each violation with its excerpt of the history, then ``faults: N``, ``fault kinds: K`` and
``violations: V``; it exits 1 when V > 0. ``--out FILE.json`` keeps the figures (faults by kind, the
peers' memory over time, the violations) and ``--logs DIR`` every process's output, both halves of the
history (``wire.jsonl``, ``soak.jsonl``) and the recording (``soak.mcap``).
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import time
from pathlib import Path
from typing import Annotated, Optional

import typer

from fabric.plant import KINDS
from robofabric.bench.common import machine

__all__ = ["command", "PLANTS"]

PLANTS = KINDS
"""Defects ``--plant`` can put in the sims (each started with ``robofabric sim --plant KIND``, fabric/plant.py)."""
SHOWN = 20
"""Violations printed in full; the rest are counted."""


def command(
    minutes: Annotated[float, typer.Option("--minutes", help="How long the class runs under the nemesis.")] = 2.0,
    students: Annotated[int, typer.Option("--students", help="Students, each on her own host with her own arm.")] = 3,
    seed: Annotated[int, typer.Option("--seed", help="The nemesis's and the students' seed.")] = 1,
    plant: Annotated[
        Optional[str], typer.Option("--plant", help=f"Plant a defect in the sims: {', '.join(PLANTS)}.")
    ] = None,
    faults: Annotated[Optional[str], typer.Option("--faults", help="Only these fault kinds (comma-separated).")] = None,
    victims: Annotated[
        Optional[str],
        typer.Option(
            "--victims",
            help="Only these take pauses, kills, partitions: sim, compute, student; "
            "each with an optional weight (sim=0.25: sims picked a quarter as often).",
        ),
    ] = None,
    until: Annotated[
        Optional[str],
        typer.Option(
            "--until",
            help="End the run a few seconds after this invariant is first broken (owners, applied, reset, ...): "
            "with --plant, the run lasts as long as catching its defect takes.",
        ),
    ] = None,
    out: Annotated[Optional[Path], typer.Option("--out", help="Write the figures as JSON here.")] = None,
    logs: Annotated[
        Optional[Path], typer.Option("--logs", help="Keep every output and the history in this folder.")
    ] = None,
    recheck: Annotated[
        Optional[Path],
        typer.Option("--recheck", help="Run no class: check the history a run kept in this --logs folder."),
    ] = None,
) -> None:
    """A class in the lab for --minutes under the nemesis; the checker reads the history: faults, violations."""
    from fabric.cli_common import UserError
    from robofabric.soak.nemesis import KINDS, VICTIMS, parse_victims
    from robofabric.soak.run import SoakConfig, fault_counts, memory_series, run_soak

    if recheck is not None:
        _recheck(recheck, out)
        return
    if minutes <= 0 or students < 2:
        raise UserError("--minutes must be positive and --students at least 2 (each queues for a neighbour's arm)")
    if plant is not None and plant not in PLANTS:
        raise UserError(f"--plant {plant!r}: expected one of {', '.join(PLANTS)}")
    from robofabric.soak.checker import INVARIANTS

    if until is not None and until not in INVARIANTS:
        raise UserError(f"--until {until!r}: expected one of {', '.join(INVARIANTS)}")
    kinds = tuple(k.strip() for k in faults.split(",") if k.strip()) if faults else KINDS
    unknown = [k for k in kinds if k not in KINDS]
    if unknown or not kinds:
        raise UserError(f"--faults {faults!r}: expected kinds among {', '.join(KINDS)}")
    try:
        weights = parse_victims(victims) if victims else dict.fromkeys(VICTIMS, 1.0)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    who = tuple(weights)
    tmp = None
    if logs is None:
        tmp = tempfile.mkdtemp(prefix="soak-")
        logs = Path(tmp)
    print(
        f"Command: robofabric bench soak --minutes {minutes:g} --students {students} --seed {seed}"
        + (f" --plant {plant}" if plant else "")
        + (f" --faults {faults}" if faults else "")
        + (f" --victims {victims}" if victims else "")
        + (f" --until {until}" if until else ""),
        flush=True,
    )
    print(f"Machine: {machine()}; load average at start {os.getloadavg()[0]:.1f}; logs in {logs}", flush=True)
    t0 = time.monotonic()
    try:
        res = run_soak(
            SoakConfig(
                minutes=minutes,
                log_dir=logs,
                students=students,
                seed=seed,
                plant=plant or "",
                kinds=kinds,
                victims=who,
                weights=tuple(weights.items()),
                until=until or "",
            )
        )
    finally:
        if tmp is not None and out is None:
            shutil.rmtree(tmp, ignore_errors=True)
    for v in res.violations[:SHOWN]:
        print(v, flush=True)
    if len(res.violations) > SHOWN:
        print(f"... and {len(res.violations) - SHOWN} more violations", flush=True)
    for line in res.bad_lines[:5]:
        print(f"unreadable history line: {line}", flush=True)
    for err in res.nemesis_errors[:10]:
        print(f"nemesis: a fault could not be made: {err}", flush=True)
    print(
        f"took {(time.monotonic() - t0) / 60:.1f} min; load average at end {os.getloadavg()[0]:.1f}; "
        f"history {len(res.history)} records; peers restarted after an unexpected exit: {res.extra.get('restarts', 0)}",
        flush=True,
    )
    for line in res.summary:
        print(line, flush=True)
    if out is not None:
        out.write_text(
            json.dumps(
                {
                    "minutes": minutes,
                    "students": students,
                    "seed": seed,
                    "plant": plant,
                    "machine": machine(),
                    "faults": fault_counts(res.history),
                    "violations": [str(v) for v in res.violations],
                    "summary": list(res.summary),
                    "memory_mb": memory_series(res.history),
                    "nemesis_errors": list(res.nemesis_errors),
                    "logs": str(logs),
                },
                indent=1,
            )
        )
    if res.violations:
        raise typer.Exit(1)


def _recheck(folder: Path, out: Path | None = None) -> None:
    """The checker on a kept history (``wire.jsonl`` and ``soak.jsonl``): violations, then the summary lines;
    ``out``: the figures as a run writes them, the violations today's checker finds (what the plot's title counts)."""
    from fabric.cli_common import UserError
    from robofabric.soak import checker
    from robofabric.soak.history import Mark, read
    from robofabric.soak.run import fault_counts, memory_series

    paths = [folder / "wire.jsonl", folder / "soak.jsonl"]
    if not all(p.exists() for p in paths):
        raise UserError(f"--recheck {folder}: expected wire.jsonl and soak.jsonl there (a --logs folder of a run)")
    history, bad = read(paths)
    violations = checker.check(history)
    for v in violations[:SHOWN]:
        print(v, flush=True)
    if len(violations) > SHOWN:
        print(f"... and {len(violations) - SHOWN} more violations", flush=True)
    for line in bad[:5]:
        print(f"unreadable history line: {line}", flush=True)
    summary = checker.summary(history, violations)
    for line in summary:
        print(line, flush=True)
    if out is not None:
        marks = {r.what: r for r in history if isinstance(r, Mark)}
        began, ended = marks.get("class", marks.get("start")), marks.get("end")
        minutes = (ended.t - began.t) / 60.0 if began is not None and ended is not None else 0.0
        out.write_text(
            json.dumps(
                {
                    "minutes": round(minutes, 1),
                    "recheck": str(folder),
                    "start": marks["start"].detail if "start" in marks else "",
                    "faults": fault_counts(history),
                    "violations": [str(v) for v in violations],
                    "summary": list(summary),
                    "memory_mb": memory_series(history),
                },
                indent=1,
            )
        )
    if violations:
        raise typer.Exit(1)


if __name__ == "__main__":
    typer.run(command)
