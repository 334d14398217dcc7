"""Fixtures of the multi-host lab tests: a lab per module, skipped (with the reason) only where
network namespaces cannot be created, and never on CI (``CI`` set): there that is a failure."""

from __future__ import annotations

from typing import Iterator

import pytest

from robofabric.lab import Lab


@pytest.fixture
def lab(lab_ok, tmp_path) -> Iterator[Lab]:
    """A fresh, empty lab for one test; removed at teardown even when the test fails."""
    with Lab(log_dir=tmp_path / "lab") as made:
        yield made
