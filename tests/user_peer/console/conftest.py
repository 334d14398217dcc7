"""Fixtures of the console's tests."""

from __future__ import annotations

import sys

import pytest


@pytest.fixture
def worlds():
    """The user worlds a test's logins opened: each closed at the end."""
    made: list = []
    yield made
    for w in made:
        w.close()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo) -> object:
    """A failed browser test says what NiceGUI told each page's console about reloading it ("reloading because
    ..."): a click that met a reload fails as a timeout that says nothing of why the page went."""
    outcome = yield
    report = outcome.get_result()  # type: ignore[attr-defined]
    browser_tests = sys.modules.get("test_console_browser")  # whose open_page the console's other modules use
    logs = getattr(item.module, "PAGE_LOGS", None) or getattr(browser_tests, "PAGE_LOGS", None)
    if report.when != "call" or not report.failed or not logs:
        return
    said = [line for lines in list(logs.values()) for line in list(lines) if "reload" in line.lower()]
    report.sections.append(("pages' reloads", "\n".join(said[-20:]) or "(no page said it reloaded)"))
    klass = getattr(item, "funcargs", {}).get("klass")  # the class console's own words (its pages, its doors)
    if klass is not None:
        report.sections.append(("the class console's output", klass.procs.output(klass.console)[-4000:]))
