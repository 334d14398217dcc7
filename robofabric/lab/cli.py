"""``robofabric lab up FILE`` and ``robofabric lab sweep``: a LAN of namespaces on this machine, by hand."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from fabric.cli_common import UserError

lab_app = typer.Typer(
    help="A multi-host LAN of network namespaces on this machine (needs root): docs/lan.md.", no_args_is_help=True
)


@lab_app.command("up")
def up(
    file: Annotated[Path, typer.Argument(help="A lab file (see robofabric/lab/spec.py, examples/lab/classroom.toml).")],
    duration: Annotated[Optional[float], typer.Option(help="Tear down after S seconds (default: Ctrl-C).")] = None,
    logs: Annotated[
        Optional[Path], typer.Option(help="Directory for the processes' output (default: a fresh one in /tmp).")
    ] = None,
) -> None:
    """Build the lab, start each host's commands, print how to reach the hosts; remove it all on Ctrl-C."""
    from robofabric.lab import Lab, LabError, namespaces_available
    from robofabric.lab.spec import load_lab, start_lab
    from fabric.session import shutdown_event

    try:
        spec = load_lab(file)
    except LabError as exc:
        raise UserError(str(exc)) from None
    ok, why = namespaces_available()
    if not ok:
        raise UserError(why)
    stop = shutdown_event()
    try:
        with Lab(subnet=spec.subnet, log_dir=logs) as lab:
            started = start_lab(spec, lab)
            print(f"lab {lab.name}: {len(lab.hosts)} host(s) on {lab.net}, logs in {lab.log_dir}", flush=True)
            for h in spec.hosts:
                host = lab.host(h.name)
                cmds = "; ".join(" ".join(a) for a in h.run) or "-"
                pids = ", ".join(str(p.pid) for p in started[h.name])
                print(
                    f"  {h.name:<10} {host.ip:<13} {('clock ' + h.clock) if h.clock else '':<9} "
                    f"ip netns exec {host.ns} bash   # robofabric {cmds} (pid {pids or '-'})",
                    flush=True,
                )
            stop.wait(duration)
            print("lab: tearing down", flush=True)
    except LabError as exc:
        raise UserError(str(exc)) from None


@lab_app.command("sweep")
def sweep() -> None:
    """Delete namespaces left by lab runs that were killed before they could clean up."""
    from robofabric.lab import sweep_stale

    removed = sweep_stale()
    print(f"removed {len(removed)} stale namespace(s)" + (f": {', '.join(removed)}" if removed else ""))


def register(app: typer.Typer) -> None:
    app.add_typer(lab_app, name="lab")
