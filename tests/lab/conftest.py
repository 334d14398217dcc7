"""Fixtures of the multi-host lab tests: a lab per module, skipped (with the reason) only where
network namespaces cannot be created, and never on CI (``CI`` set): there that is a failure."""

from __future__ import annotations

import os
from typing import Iterator

import pytest

from robofabric.lab import Lab, namespaces_available, sweep_stale


@pytest.fixture(scope="session")
def lab_ok() -> None:
    ok, why = namespaces_available()
    if not ok:
        if os.environ.get("CI"):
            pytest.fail(f"lab tests cannot run on CI (CI={os.environ['CI']!r}): {why}", pytrace=False)
        print(f"lab tests skipped: {why}")
        pytest.skip(why)
    sweep_stale()  # namespaces of earlier runs that were killed before they could clean up


@pytest.fixture
def lab(lab_ok, tmp_path) -> Iterator[Lab]:
    """A fresh, empty lab for one test; removed at teardown even when the test fails."""
    with Lab(log_dir=tmp_path / "lab") as made:
        yield made
