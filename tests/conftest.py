"""Fixtures shared by every test package: a real router on a unique loopback port, clients, processes."""

from __future__ import annotations

import os
import subprocess
import sys
import uuid
from typing import Any, Iterator

import pytest
from hypothesis import HealthCheck, settings

from fabric.session import Fabric
from robofabric.pytest_hang_watch import pytest_configure, pytest_runtest_protocol  # noqa: F401 (hooks)
from robofabric.testing import ProcessGroup, client, free_port, router_config


# Property tests judge logic, not speed: hypothesis's per-example deadline (200 ms) and its too-slow health
# check fail them on a loaded box (CI saw a FakeClock property "fail" at load 18 with no falsifying example).
settings.register_profile("robofabric", deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("robofabric")


# `make test` runs the suite on four pytest-xdist workers (`-n 4 --dist loadgroup`). The tests that load the whole
# box go in two units of work, each run one test after another on one worker: the browsers (Chromium drawing in
# software GL, the console's class worlds: three at once took the box to load 37) with the floods, and the classes
# (soaks and namespace labs, CPU hogs beside paused processes, paces at full rate and 0.3 s leases). Two browsers or
# two classes at once judge each other's pace, not the code's; one of each runs beside the other's, and the rest
# share the other two workers. The two units go out first: each is longer than any other worker's whole share.
HEAVY: dict[str, tuple[str, ...]] = {
    "heavy-browser": (
        "tests/user_peer/console/",
        "tests/user_peer/test_view_web.py",
        "tests/user_peer/test_web_pages.py",
        "tests/robofabric/bench/test_bench_console.py",
        # the floods (a flooder as fast as it can go, 6,000 declarations, a login flood) load the whole box too: one
        # at a time, in the shorter unit (at load 16 beside the classes the declarations stalled the router 20 s)
        "tests/robofabric/bench/test_bench_flood.py",
        "tests/robofabric/bench/test_bench_declflood.py",
        "tests/robofabric/bench/test_bench_secure_flood.py",
    ),
    "heavy-class": (
        "tests/robofabric/soak/",
        "tests/lab/",
        "tests/user_peer/test_pause_ride_out.py",
        "tests/sim_peer/replica/test_pause.py",
        "tests/sim_peer/replica/test_paused_standby.py",
        "tests/ownership/test_router_stall.py",
        # a pace at full rate and 0.3 s leases: at load 37 beside Chromium the first logged 0.36x of its full rate
        # and the second's starved authority waited out its deaf guard (the grouped run of 2026-11-29)
        "tests/user_peer/test_view_class.py",
        "tests/robofabric/bench/test_bench_ownership.py",
    ),
}


PAGES: tuple[str, ...] = (
    "tests/user_peer/console/",
    "tests/user_peer/test_view_web.py",
    "tests/user_peer/test_web_pages.py",
    "tests/robofabric/bench/test_bench_console.py",
)
"""The tests of pages in Chromium: on a pytest-xdist worker they run at :data:`PAGES_NICE`, with every process they
start (robofabric/priority.py): a student's page and its server are not three other suites' neighbours in a
classroom, and starved here their sockets dropped and their pages were reloaded (half of whole runs' failures)."""
PAGES_NICE = -10
_nice_now = [0]
_keeper: list = [None]  # the NiceKeeper holding the pages' priority while they run


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item: pytest.Item) -> None:
    """Before the test's fixtures: its priority (:data:`PAGES`), where the suite runs on pytest-xdist workers."""
    if "PYTEST_XDIST_WORKER" not in os.environ:
        return
    nice = PAGES_NICE if item.nodeid.startswith(PAGES) else 0
    if nice != _nice_now[0]:
        from robofabric.priority import NiceKeeper, set_tree_nice

        if _keeper[0] is not None:
            _keeper[0].stop()
            _keeper[0] = None
        if nice:  # held while the pages' tests run: Chromium sets its renderers' own values (robofabric/priority.py)
            _keeper[0] = NiceKeeper(nice).start()  # not allowed (no privilege): as before
        else:
            set_tree_nice(nice)
        _nice_now[0] = nice


def work_unit(nodeid: str) -> str:
    """The unit of work a test goes in under ``--dist loadgroup``: a heavy test in its :data:`HEAVY` unit, any other
    test with the rest of its module, so that a module's shared world (a module fixture) is built by one worker only."""
    for unit, paths in HEAVY.items():
        if nodeid.startswith(paths):
            return unit
    return nodeid.split("::", 1)[0]


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log: object) -> object:
    """``--dist loadgroup`` with the units of :func:`work_unit`, decided on the controller from each test's path, the
    heavy units dealt first (xdist deals the units with the most tests first, and the classes' unit has few).

    Not xdist's ``xdist_group`` mark: its worker appends the group to the node id, which pytest 9.2's structured
    node ids ignore (pytest-xdist issue 1386), so every worker ran the console's class worlds at once."""
    if config.getvalue("dist") != "loadgroup":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class ByWorkUnit(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return work_unit(nodeid)

        distributed = False

        def schedule(self) -> None:
            super().schedule()
            self.distributed = self.collection is not None

        def _assign_work_unit(self, node: Any) -> None:
            for unit in reversed(HEAVY):
                if unit in self.workqueue:
                    self.workqueue.move_to_end(unit, last=False)
            fresh = self.distributed and self._pending_of(self.assigned_work.get(node, {})) == 0
            super()._assign_work_unit(node)
            if fresh and not self.workqueue and not node.shutting_down:
                # A crashed worker's replacement given the last unit: a worker holds its last test until it hears
                # of a next one or of the end, and a fresh one has no earlier test whose end would bring either.
                # Streak run 1 (2026-12-04) sat so for 20 min after the hang watch's kill: the end is sent with it.
                node.shutdown()

        def remove_node(self, node: Any) -> str | None:
            """A worker gone, at the end or crashed (the hang watch ends a hung test's worker). xdist 3.8's
            ``LoadScopeScheduling`` put the crashed test back in line with the rest of its unit, so each replacement
            ran it again, hung again and was ended again, until xdist's limit of restarts. Here the crashed test is
            reported once, as xdist's ``load`` does, and the replacement runs the rest of its unit. (A crashed
            worker's collection stays registered: the scheduler counts the collections against the initial
            workers, and a run whose count fell short never ended: b94332a's run 4.)"""
            workload = self.assigned_work.pop(node)
            crashed = next((t for unit in workload.values() for t, done in unit.items() if not done), None)
            if crashed is None:
                return None
            workload[self._split_scope(crashed)][crashed] = True
            self.workqueue.update((scope, unit) for scope, unit in workload.items() if not all(unit.values()))
            for other in self.assigned_work:
                self._reschedule(other)
            return crashed

    return ByWorkUnit(config, log)  # type: ignore[arg-type]


@pytest.fixture
def world() -> str:
    """A world name unique to the test, so concurrent tests never hear each other."""
    return f"t{uuid.uuid4().hex[:8]}"


@pytest.fixture
def router(world: str) -> Iterator[tuple[Fabric, int]]:
    """An in-process router (embedded profile) on a fresh port; yields (fabric, port)."""
    port = free_port()
    fab = Fabric(router_config(world, port), kind="router", peer_id="router")
    try:
        yield fab, port
    finally:
        fab.close()


@pytest.fixture
def connect(world: str, router: tuple[Fabric, int]):
    """Factory of client peers connected to the test's router; all closed at the end."""
    made: list[Fabric] = []

    def make(kind: str = "tool", peer_id: str | None = None) -> Fabric:
        fab = client(world, router[1], kind=kind, peer_id=peer_id)
        made.append(fab)
        return fab

    yield make
    for fab in made:
        fab.close()


@pytest.fixture
def procs(tmp_path) -> Iterator[ProcessGroup]:
    """Child processes of the test, logged under tmp_path and ended by pid at teardown."""
    group = ProcessGroup(tmp_path)
    try:
        yield group
    finally:
        group.close()


@pytest.fixture(scope="session")
def lab_ok() -> None:
    """The multi-host tests (tests/lab, the soak's) need network namespaces: skipped with the reason only where
    they cannot be made, and never on CI (``CI`` set), where that is a failure."""
    import os

    from robofabric.lab import namespaces_available, sweep_stale

    ok, why = namespaces_available()
    if not ok:
        if os.environ.get("CI"):
            pytest.fail(f"multi-host tests cannot run on CI (CI={os.environ['CI']!r}): {why}", pytrace=False)
        print(f"multi-host tests skipped: {why}")
        pytest.skip(why)
    sweep_stale()  # namespaces of earlier runs that were killed before they could clean up


# Modules that run a program at import or on a query to describe the machine (platform.processor(),
# ctypes.util.find_library, glfw's version check when MuJoCo's viewer module loads): probes, not processes a
# test starts.
_PROBING_MODULES = {"platform", "ctypes.util", "glfw.library"}


def _caller_module() -> str:
    """The module that asked subprocess for a process (the first frame outside subprocess and this file)."""
    frame = sys._getframe(2)
    while frame is not None and frame.f_globals.get("__name__") in {"subprocess", __name__}:
        frame = frame.f_back
    return frame.f_globals.get("__name__", "?") if frame is not None else "?"


@pytest.fixture(autouse=True)
def _fast_tests_start_no_process(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """The fast suite (``make test-fast``) is in-process only: a test that starts a child process is slow, and
    must say so with ``@pytest.mark.slow``. A fast test that starts one fails here, naming the program."""
    if request.node.get_closest_marker("slow") is not None:
        yield
        return
    started: list[str] = []
    real_init = subprocess.Popen.__init__

    def spy(self: subprocess.Popen, args, *rest, **kwargs) -> None:  # type: ignore[no-untyped-def]
        if _caller_module() not in _PROBING_MODULES:
            argv = [args] if isinstance(args, (str, bytes, os.PathLike)) else list(args)
            started.append(" ".join(os.fsdecode(a) for a in argv)[:160])
        real_init(self, args, *rest, **kwargs)

    monkeypatch.setattr(subprocess.Popen, "__init__", spy)
    yield
    if started:
        pytest.fail(
            f"a fast test started {len(started)} process(es), e.g. {started[0]!r}: mark it "
            "@pytest.mark.slow (make test-fast runs in-process tests only)",
            pytrace=False,
        )
