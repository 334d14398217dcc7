"""The units ``--dist loadgroup`` deals out to xdist's workers (tests/conftest.py): the box's heavy tests in two
(browsers, classes), any other test with its module. A heavy entry that names nothing would let its tests run beside each other unseen."""

from __future__ import annotations

from pathlib import Path
from types import ModuleType

import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture
def units(request: pytest.FixtureRequest) -> ModuleType:
    """tests/conftest.py as pytest loaded it: ``import conftest`` may give another folder's conftest."""
    mine = ROOT / "tests" / "conftest.py"
    found = [p for p in request.config.pluginmanager.get_plugins() if Path(getattr(p, "__file__", "") or "") == mine]
    assert found, "tests/conftest.py is not among pytest's plugins"
    return found[0]


def test_every_heavy_entry_names_a_test_file_or_folder_of_the_tree(units: ModuleType) -> None:
    missing = [entry for paths in units.HEAVY.values() for entry in paths if not (ROOT / entry).exists()]
    assert not missing, f"HEAVY names what the tree does not hold: {missing}"


def test_the_heavy_tests_share_their_two_units_and_the_others_go_with_their_module(units: ModuleType) -> None:
    work_unit = units.work_unit
    assert work_unit("tests/user_peer/console/test_console_browser.py::test_a") == "heavy-browser"
    assert work_unit("tests/user_peer/test_web_pages.py::test_a") == "heavy-browser"
    assert work_unit("tests/lab/test_lab_faults.py::test_b[x]") == "heavy-class"
    assert work_unit("tests/robofabric/soak/test_soak_ci.py::test_c") == "heavy-class"
    assert work_unit("tests/fabric/test_keys.py::test_c") == work_unit("tests/fabric/test_keys.py::test_d[1@2]")
    assert work_unit("tests/fabric/test_keys.py::test_c") != work_unit("tests/fabric/test_rate.py::test_c")
