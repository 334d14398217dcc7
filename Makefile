# The two commands: `make demo` and `make test` (`make test-fast`: without the slow tests). Each creates .venv when missing.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
STAMP_TEST := $(VENV)/.installed-test

.PHONY: demo test test-fast lint format install clean bench

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip

$(STAMP): pyproject.toml | $(PY)
	$(PY) -m pip install -q -e ".[all]"
	touch $@

$(STAMP_TEST): pyproject.toml | $(PY)
	$(PY) -m pip install -q -e ".[test]"
	touch $@ $(STAMP)

# axe-core (npm), which the console's accessibility test runs in Chromium; pinned by tests/a11y/package-lock.json
AXE := tests/a11y/node_modules/axe-core/axe.min.js
$(AXE): tests/a11y/package.json tests/a11y/package-lock.json
	@if command -v npm >/dev/null 2>&1; then (npm ci --prefix tests/a11y --no-audit --no-fund --loglevel=error && touch $@) \
	  || echo "warning: npm ci of tests/a11y failed: the console's axe-core test will try again, then fail" >&2; \
	else echo "warning: no npm (apt-get install npm): the console's axe-core test will fail" >&2; fi

# tf2_msgs, std_srvs, nav2_msgs (NavigateToPose) and control_msgs (FollowJointTrajectory), which ROS 2 Kilted's wheels lack, generated and compiled into .venv with the wheels' rosidl
# tools and g++ (user_peer/ros2/msgbuild.py, ~10 s); a failure is said here and the ROS 2 tests that need them fail
ROS_MSGS := $(VENV)/.ros-msgs
$(ROS_MSGS): user_peer/ros2/msgbuild.py $(STAMP_TEST)
	@($(PY) -m user_peer.ros2.msgbuild --force && touch $@) \
	  || echo "warning: tf2_msgs/std_srvs/nav2_msgs/control_msgs not built (above): the ROS 2 bridge's TF, ownership service and action tests will fail" >&2

install: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/robofabric demo --out out/demo

# Both keep bytecode (PYTHONDONTWRITEBYTECODE emptied, where a shell sets it): with none, every run compiled each
# module again and pytest rewrote each test module's asserts again, half of the fast suite's collection (docs/testing.md)
# On four pytest-xdist workers: the box's heavy tests in two units of one worker each (browsers, classes), the rest
# with their modules on the other two (tests/conftest.py, docs/testing.md)
test: $(STAMP_TEST) $(AXE) $(ROS_MSGS)
	PYTHONDONTWRITEBYTECODE= $(PY) -m pytest -q -n 4 --dist loadgroup --durations=25

# the fast suite: no process-spawning or multi-second tests (those are marked slow)
test-fast: $(STAMP_TEST) $(ROS_MSGS)
	PYTHONDONTWRITEBYTECODE= $(PY) -m pytest -q -m "not slow" -n 4

# the linter, the formatter's check and the type checker alone (tests/test_lint.py runs both in `make test`)
lint: $(STAMP_TEST)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/mypy

# the formatter, as the check above wants the tree
format: $(STAMP_TEST)
	$(VENV)/bin/ruff format .

# every benchmark, shortened (`robofabric bench all` without --quick for the figures in docs/benchmarks.md)
bench: $(STAMP)
	$(VENV)/bin/robofabric bench all --quick

clean:
	rm -rf $(VENV) out .pytest_cache .hypothesis .mypy_cache .ruff_cache
