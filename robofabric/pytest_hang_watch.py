"""The pytest plug-in of :mod:`robofabric.hang_watch`: every test is watched from its setup to its teardown's end.

``tests/conftest.py`` takes its hooks; another suite loads it with ``-p robofabric.pytest_hang_watch``.
``ROBOFABRIC_HANG_GRACE_S`` sets the grace after a test's timeout (its own tests' short one)."""

from __future__ import annotations

import os
from typing import Iterator

import pytest

from robofabric.hang_watch import HangWatch, run_stderr

_watch: HangWatch | None = None


def pytest_configure(config: pytest.Config) -> None:
    """Before any test's output is captured: the watch keeps the run's own stderr (see :func:`run_stderr`)."""
    global _watch
    grace = float(os.environ.get("ROBOFABRIC_HANG_GRACE_S", "0") or 0)
    _watch = HangWatch(run_stderr(), **({"grace_s": grace} if grace > 0 else {}))


def timeout_of(item: pytest.Item) -> float:
    """The test's pytest-timeout limit: its marker's, else the run's (``--timeout``, else the ini's)."""
    marker = item.get_closest_marker("timeout")
    if marker is not None:
        value = marker.args[0] if marker.args else marker.kwargs.get("timeout")
        if value is not None:
            return float(value)
    option = item.config.getoption("timeout", default=None)
    if option is not None:
        return float(option)
    return float(item.config.getini("timeout") or 0)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Iterator[None]:
    if _watch is not None:
        _watch.arm(item.nodeid, timeout_of(item))
    try:
        yield
    finally:
        if _watch is not None:
            _watch.disarm()
