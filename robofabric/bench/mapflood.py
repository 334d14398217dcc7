"""``robofabric bench mapflood``: a student building maps under new names, in a class world.

    robofabric bench mapflood [--builds 1400] [--out FILE.md]

A class world made with ``robofabric secure init``: a router, a sim and a compute peer under their logins.
Once the compute peer has folded scans, mallory (her login, in this process) asks ``build`` on
``srv/map/m{i}/by/mallory`` for ``--builds`` new names, then once more with threshold 0.001 on the class's
name. Measured: how many builds were kept and refused (and the first refusal's reason), the compute
peer's RSS before and after, the seconds per build asked, and how many times the class's map (``map/map``)
was published meanwhile. Issue 30 saw 1,400 such builds grow a compute peer from 142 to 528 MB for good, and her
threshold 0.001 replace the class's map.
"""

from __future__ import annotations

import tempfile
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import typer

from robofabric.testing import ProcessGroup, free_port, robofabric_cmd, wait_until
from robofabric.bench.common import TableOut, append, machine, proc_rss_mb


@dataclass(frozen=True, slots=True)
class MapFloodResult:
    """``builds`` new names asked: kept, refused, the compute peer's RSS (MB) and the class map's publications."""

    builds: int
    kept: int
    refused: int
    reason: str
    seconds_per_build: float
    rss_before_mb: float
    rss_after_mb: float
    class_map_published: int
    low_threshold: str


def run_mapflood(builds: int, tmp: Path) -> MapFloodResult:
    """Start the class world under ``tmp``, let mallory ask ``builds`` builds under new names, end it all."""
    from fabric import keys
    from fabric.config import FabricConfig
    from fabric.interfaces import MapReply, MapRequest, OccupancyGrid, ServiceError
    from robofabric.secure import init
    from fabric.session import Fabric

    world = f"maps{uuid.uuid4().hex[:6]}"
    ep = f"tcp/127.0.0.1:{free_port()}"
    made = init(tmp / "class", users=["mallory"], listen=[ep])
    files = made.clients
    with ProcessGroup(tmp) as procs:
        router = procs.start(robofabric_cmd("router", "--zenoh-config", str(made.router)), name="router")
        wait_until(
            lambda: "listening" in procs.output(router), timeout=30, what="router", seen=lambda: procs.output(router)
        )
        sim = procs.start(
            robofabric_cmd("sim", "--scene", "combined", "--world", world, "--zenoh-config", str(files["sim"])),
            name="sim",
        )
        compute = procs.start(
            robofabric_cmd("compute", "--world", world, "--zenoh-config", str(files["compute"])), name="compute"
        )
        wait_until(
            lambda: "serving" in procs.output(compute),
            timeout=90,
            what="the compute peer",
            seen=lambda: procs.output(compute)[-1500:],
        )
        with Fabric(
            FabricConfig(world=world, config_file=str(files["mallory"])), kind="user", peer_id="mallory"
        ) as mallory:
            published: list[str] = []
            mallory.subscribe(keys.map_key(world, "map"), lambda k, m: published.append(k), expected=OccupancyGrid)
            status = keys.srv_asked(world, "map", "map", "mallory")

            def scans() -> int:
                try:
                    return mallory.rpc.call(status, MapRequest("status"), timeout=5.0, expected=MapReply).scans
                except ServiceError:
                    return 0

            wait_until(lambda: scans() > 20, timeout=90, what="scans folded by the compute peer")
            time.sleep(2.0)  # settle: the first scans' allocations
            rss0 = proc_rss_mb(compute.pid)
            kept, reasons = 0, []
            t0 = time.perf_counter()
            for i in range(builds):
                try:
                    mallory.rpc.call(
                        keys.srv_asked(world, "map", f"m{i}", "mallory"),
                        MapRequest("build", name=f"m{i}"),
                        timeout=10.0,
                        expected=MapReply,
                    )
                    kept += 1
                except ServiceError as exc:
                    reasons.append(exc.reason)
            per = (time.perf_counter() - t0) / max(builds, 1)
            try:
                mallory.rpc.call(status, MapRequest("build", threshold=0.001), timeout=10.0, expected=MapReply)
                low = "kept"
            except ServiceError as exc:
                low = f"refused: {exc.reason}"
            time.sleep(2.0)
            rss1 = proc_rss_mb(compute.pid)
        procs.kill(compute, sig=15)
        procs.kill(sim, sig=15)
    return MapFloodResult(
        builds, kept, len(reasons), reasons[0] if reasons else "", per, rss0, rss1, len(published), low
    )


def table(r: MapFloodResult) -> str:
    head = (
        "| new names asked | kept | refused | s per build | compute RSS before / after MB | class map published | "
        "threshold 0.001 |\n|---|---|---|---|---|---|---|"
    )
    row = (
        f"| {r.builds} | {r.kept} | {r.refused} | {r.seconds_per_build:.3f} | {r.rss_before_mb:.0f} / {r.rss_after_mb:.0f} | "
        f"{r.class_map_published} | {r.low_threshold} |"
    )
    why = f"\n\nfirst refusal: {r.reason}" if r.reason else ""
    return f"{head}\n{row}{why}"


def command(
    builds: Annotated[int, typer.Option(help="Builds under new map names mallory asks.")] = 1400,
    out: TableOut = None,
) -> None:
    """A student building maps under new names: what the compute peer keeps, refuses and weighs."""
    with tempfile.TemporaryDirectory() as tmp:
        r = run_mapflood(builds, Path(tmp))
    text = f"robofabric bench mapflood --builds {builds}; {machine()}\n\n{table(r)}"
    print(text)
    append(out, text)
