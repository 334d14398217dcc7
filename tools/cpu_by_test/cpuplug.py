"""A pytest plug-in (``PYTEST_PLUGINS=cpuplug``): each test's own CPU in the pytest process, one line per test
in ``RF_CPU_LOG`` (argv ``INPROC``), beside the lines ``sitecustomize`` writes for the processes it starts."""

import os
import time

import pytest

_LOG = os.environ.get("RF_CPU_LOG")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    c0, w0 = time.process_time(), time.time()
    yield
    if _LOG:
        with open(_LOG, "a") as f:
            f.write(f"{time.process_time() - c0:.3f}\t{time.time() - w0:.2f}\t{item.nodeid}\tINPROC\n")
