# The two commands of the README: `make demo` and `make test`.
# Each creates .venv/ when missing, installs the requirements, builds the
# messages and the compiled core (collres_ros/core/_native) and installs collres_ros
# (editable); a second run only checks stamps.

PYTHON ?= python3.11
VENV := .venv
VPY := $(VENV)/bin/python
PIP := $(VPY) -m pip --disable-pip-version-check -q
MSG_STAMP := collres_ros/msg/.build-stamp
INTERFACE_INPUTS := CMakeLists.txt package.xml cmake/build_interfaces.py $(wildcard cmake/*.cmake) \
	$(wildcard msg/*.msg) $(wildcard srv/*.srv) $(wildcard src/*.h) $(wildcard src/*.cpp) \
	$(wildcard cmake/tf2_msgs/*.*) $(wildcard cmake/tf2_msgs/msg/*.msg)
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST

.PHONY: demo test setup test-setup bench goldens sanitize clean

demo: setup
	$(VENV)/bin/collres_demo

test: setup test-setup
	$(VPY) -m pytest test

# then the package's bytecode, compiled ahead (only what changed): an editable install
# compiles none, and where PYTHONDONTWRITEBYTECODE is set (CI containers) every process
# compiled every collres_ros module again, 0.08 s of each collres_node start
setup: $(VENV)/.editable-stamp
	@$(VPY) -m compileall -q collres_ros

test-setup: $(VENV)/.test-deps-stamp

$(VPY):
	$(PYTHON) -m venv $(VENV)
	$(PIP) install -U pip "setuptools>=70.1,<80" wheel

$(VENV)/.deps-stamp: requirements.txt | $(VPY)
	$(PIP) install -r requirements.txt
	touch $@

$(VENV)/.test-deps-stamp: requirements-test.txt $(VENV)/.deps-stamp
	$(PIP) install -r requirements-test.txt
	touch $@

$(MSG_STAMP): $(INTERFACE_INPUTS) $(VENV)/.deps-stamp
	$(VPY) cmake/build_interfaces.py collres_ros
	touch $@

# setuptools' "Editable installation ... folders with the same name" notice is informational
# (the repo root is meant to be importable): silenced, nothing for a user to act on
$(VENV)/.editable-stamp: setup.py pyproject.toml $(wildcard scripts/collres_*) $(MSG_STAMP)
	PYTHONWARNINGS="ignore:Editable installation" $(PIP) install --no-deps --no-build-isolation -e .
	touch $@

# BENCH_ARGS e.g. --sizes 10 100 --peer-venv DIR (default ~/.cache/collres_ros/peer-venv,
# created when missing with pip install mujoco pybullet rapier3d)
bench: setup
	$(VPY) bench/bench_step.py $(BENCH_ARGS)

goldens: setup
	$(VPY) tools/regenerate_goldens.py

# The core's sources with AddressSanitizer + UBSan, and its fuzz driver (fuzz/fuzz_core.cpp):
# FUZZ_CASES generated cases from FUZZ_SEED (fixed: the same cases on every run), or FUZZ_FILES
# (a corpus of byte files) instead. Not part of `make test` (the build takes minutes); CI
# runs it after the tests (.ci/run).
FUZZ_CASES ?= 20000
FUZZ_SEED ?= 1
sanitize: setup
	cmake -S fuzz -B build/sanitize -DPython3_EXECUTABLE=$(abspath $(VPY)) \
		-DBoost_NO_WARN_NEW_VERSIONS=ON -Wno-dev > /dev/null
	cmake --build build/sanitize --parallel 2
	ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1 \
		build/sanitize/collres_fuzz_core $(or $(FUZZ_FILES),$(FUZZ_CASES) $(FUZZ_SEED))

clean:
	rm -rf build collres_ros/msg collres_ros/srv collres_ros/_lib collres_ros/_interfaces collres_ros/*.so collres_ros/core/_native*.so \
		demo_out bench_out/step.json
