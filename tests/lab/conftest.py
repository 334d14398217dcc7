"""Fixtures of the multi-host lab tests: a lab per module, skipped (with the reason) only where
network namespaces cannot be created."""

from __future__ import annotations

from typing import Iterator

import pytest

from fabric.lab import Lab, namespaces_available, sweep_stale


@pytest.fixture(scope="session")
def lab_ok() -> None:
    ok, why = namespaces_available()
    if not ok:
        print(f"lab tests skipped: {why}")
        pytest.skip(why)
    sweep_stale()  # namespaces of earlier runs that were killed before they could clean up


@pytest.fixture
def lab(lab_ok, tmp_path) -> Iterator[Lab]:
    """A fresh, empty lab for one test; removed at teardown even when the test fails."""
    with Lab(log_dir=tmp_path / "lab") as made:
        yield made
