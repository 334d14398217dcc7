"""Every benchmark of robofabric, and the one table that registers them.

A benchmark is a module ``robofabric/bench/NAME.py`` that defines ``command``: a typer function whose
options are the benchmark's flags and whose docstring is its ``--help``. It is registered by one line in
:data:`BENCHMARKS` below, and nowhere else: ``robofabric bench NAME`` (:mod:`robofabric.bench.cli`),
``robofabric bench list``, ``robofabric bench all`` and ``tools/bench_all.sh`` are all built from this
table. Each entry also says how the figures in docs/benchmarks.md were measured (``full``) and what a
smoke-sized run is (``quick``), so the documented command lines and the runnable ones cannot drift
(tests/robofabric/bench/test_bench_registry.py checks both).

This package sits at the top of the import layers (interfaces, fabric, ownership, peers, then
``robofabric``), so a benchmark may use any peer package; nothing below imports it.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Callable

__all__ = ["Benchmark", "BENCHMARKS", "get", "names"]


@dataclass(frozen=True, slots=True)
class Benchmark:
    """One ``robofabric bench NAME``: where its code is, what it measures, and its documented and quick runs."""

    name: str
    """The subcommand: ``robofabric bench NAME``."""
    module: str
    """The module (under ``robofabric.bench``) whose ``command`` runs it."""
    measures: str
    """One line for ``robofabric bench --help`` and ``bench list``."""
    full: tuple[str, ...] = ()
    """The arguments of the figures in docs/benchmarks.md (``bench all`` runs these)."""
    quick: tuple[str, ...] = ()
    """A smoke-sized run, seconds to a minute on two cores (``bench all --quick``)."""
    out: str = "append"
    """What ``--out PATH`` is: ``append`` / ``write`` a markdown table to the file, ``dir`` a folder for logs."""
    needs: str = ""
    """A requirement ``bench all`` checks before running it: ``netns`` (root, network namespaces) or nothing."""

    def command(self) -> Callable[..., None]:
        """The typer function (imported on demand; the module keeps its heavy imports inside functions)."""
        return importlib.import_module(f"robofabric.bench.{self.module}").command

    def argv(self, *, quick: bool = False) -> list[str]:
        """The command line after ``robofabric``: ``["bench", NAME, ...the full or quick arguments]``."""
        return ["bench", self.name, *(self.quick if quick else self.full)]

    def unavailable(self) -> str | None:
        """Why it cannot run on this machine now, or None."""
        if self.needs == "netns":
            from robofabric.lab import namespaces_available

            ok, why = namespaces_available()
            return None if ok else why
        return None


BENCHMARKS: tuple[Benchmark, ...] = (
    Benchmark(
        "transport",
        "transport",
        "240-ray scans through a router, separate processes, side by side with MQTT",
        full=("--rates", "20,100,1000,0"),
        quick=("--rates", "1000", "--duration", "1"),
    ),
    Benchmark(
        "sim",
        "sim",
        "real-time factor of the headless sim, one LIDAR scan's cost, N mobile robots",
        full=("--seconds", "10", "--counts", "1,10,50"),
        quick=("--seconds", "1", "--counts", "1,5"),
        out="write",
    ),
    Benchmark(
        "ik",
        "ik",
        "IK solve times (closed form, numerical, CasADi) and the IK query round trip",
        full=("--n", "2000", "--queries", "1000"),
        quick=("--n", "200", "--queries", "100"),
    ),
    Benchmark(
        "nav",
        "nav",
        "map update per scan; Hybrid A* beside OMPL on a 20 m map at 5 cm",
        full=("--queries", "50", "--scans", "500"),
        quick=("--queries", "3", "--scans", "50"),
    ),
    Benchmark(
        "ownership",
        "ownership",
        "ownership handover among N users; new owner after SIGKILL / SIGSTOP",
        full=("--users", "10,50,100", "--kills", "3"),
        quick=("--users", "5", "--kills", "1"),
    ),
    Benchmark(
        "failover",
        "failover",
        "sim failover: take-over time and state error after the primary's SIGKILL",
        full=("--kills", "10"),
        quick=("--kills", "1"),
        out="write",
    ),
    Benchmark(
        "record",
        "record",
        "MCAP recording throughput, loss and CPU; replay timing",
        full=("--scales", "1,8,16", "--fast", "64"),
        quick=("--scales", "1", "--robots", "2", "--duration", "2"),
    ),
    Benchmark(
        "viewer",
        "viewer",
        "cost of drawing one message in the Rerun viewer, per message type",
        full=("--n", "1000", "--grids", "50", "--arms", "8", "--bases", "8", "--seconds", "5"),
        quick=("--n", "200", "--grids", "20"),
    ),
    Benchmark(
        "flood",
        "flood",
        "an owner's command latency, peers' memory and logs while others flood the world",
        full=("--scale", "1"),
        quick=("--scale", "0.1", "--settle", "2"),
        out="dir",
    ),
    Benchmark(
        "secure",
        "secure",
        "scans and IK round trips over TCP, TCP + access control, TLS + access control; "
        "an owner driving beside one login's flood",
        full=("--rounds", "3"),
        quick=("--rounds", "1", "--duration", "1", "--queries", "50", "--flood-seconds", "2"),
    ),
    Benchmark(
        "class",
        "klass",
        "a class of N students (processes), each owning an arm and a base: nothing lost, move times, sim pace",
        full=("--students", "1,4,8,16,32", "--seconds", "40"),
        quick=("--students", "1,2", "--seconds", "8"),
    ),
    Benchmark(
        "class-nav",
        "class_nav",
        "N students do Test B at once in the warehouse: reached, plan times, stops, collisions, robot cells in maps",
        full=("--bases", "4"),
        quick=("--bases", "2"),
    ),
    Benchmark(
        "declflood",
        "declflood",
        "a login declaring N subscribers and closing: router stall and memory, owners keep their robots",
        full=("--counts", "6000,20000"),
        quick=("--counts", "2000"),
    ),
    Benchmark(
        "mapflood",
        "mapflood",
        "a student building maps under new names: what the compute peer keeps, refuses and weighs",
        full=("--builds", "1400"),
        quick=("--builds", "20"),
    ),
    Benchmark(
        "shards",
        "shards",
        "one world of N mobile robots over 1, 2, 4 sim processes: pace, CPU per robot, mirror lag, command latency",
        full=("--robots", "32", "--sims", "1,2,4", "--seconds", "20"),
        quick=("--robots", "4", "--sims", "1,2", "--seconds", "4"),
    ),
    Benchmark(
        "lab",
        "lab",
        "recovery times in a lab of network namespaces: partition, router loss, lost sim",
        full=("--runs", "5"),
        quick=("--runs", "1"),
        needs="netns",
    ),
    Benchmark(
        "console",
        "console",
        "N browser pages on one console server, each driving its base: view lag in the page, key to motion, server CPU",
        full=("--pages", "1,10,20", "--seconds", "20"),
        quick=("--pages", "2", "--seconds", "5"),
    ),
    Benchmark(
        "paper",
        "paper",
        "the paper's evaluation side by side: data usage (zenoh and MQTT at 10-600 Hz, payload and wire bytes, "
        "MB/min), resources per application (Table 4), and 5 students' delay on robots they do not own",
        full=("--rates", "10,20,50,100,200,600", "--resources", "--multi-user"),
        quick=("--quick",),
    ),
    Benchmark(
        "ros2",
        "ros2",
        "N mobile robots through the ROS 2 bridge to an rclpy node: added latency, loss, bridge CPU",
        full=("--robots", "8", "--seconds", "20"),
        quick=("--robots", "1", "--seconds", "6"),
    ),
    Benchmark(
        "soak",
        "soak",
        "a class in the lab for M minutes under a seeded nemesis, then the checker: faults by kind, violations, peers' memory",
        full=("--minutes", "60", "--students", "3", "--seed", "1"),
        quick=("--minutes", "1", "--students", "2"),
        out="write",
        needs="netns",
    ),
)


def names() -> list[str]:
    """Registered benchmark names, in the table's order."""
    return [b.name for b in BENCHMARKS]


def get(name: str) -> Benchmark:
    """The benchmark called ``name``; KeyError naming the known ones otherwise."""
    for b in BENCHMARKS:
        if b.name == name:
            return b
    raise KeyError(f"no benchmark {name!r}; known: {', '.join(names())}")
