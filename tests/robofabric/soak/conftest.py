"""The soak's lab tests need network namespaces: skipped (with the reason) only where they cannot be made,
and never on CI (``CI`` set), where that is a failure."""

from __future__ import annotations

import os

import pytest

from robofabric.lab import namespaces_available, sweep_stale


@pytest.fixture(scope="session")
def lab_ok() -> None:
    ok, why = namespaces_available()
    if not ok:
        if os.environ.get("CI"):
            pytest.fail(f"soak tests cannot run on CI (CI={os.environ['CI']!r}): {why}", pytrace=False)
        pytest.skip(why)
    sweep_stale()
