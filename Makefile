# Two commands that work on a fresh machine, each doing its own set-up:
#   make demo   - run the whole node graph on the bundled default flight and write out/demo/
#   make test   - run the test suite
#   make fuzz   - the property tests with 10 000 random examples each (minutes; not in CI)
SHELL := /bin/bash
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
RUNTIME_STAMP := $(VENV)/.runtime-installed
DEV_STAMP := $(VENV)/.dev-installed

# DDS discovery stays on this machine; each run picks its own domain.
export ROS_AUTOMATIC_DISCOVERY_RANGE := LOCALHOST
DOMAIN = $${ROS_DOMAIN_ID:-$$(( RANDOM % 100 + 1 ))}

.PHONY: demo test lint bench bench-accuracy bench-node bench-sweep bench-load bench-multihost \
	bench-stress fuzz clean

$(VENV)/bin/python:
	$(PYTHON) -m venv $(VENV)

$(RUNTIME_STAMP): requirements.txt setup.py | $(VENV)/bin/python
	$(PY) -m pip install --quiet --disable-pip-version-check -r requirements.txt
	$(PY) -m pip install --quiet --disable-pip-version-check --no-deps -e .
	touch $@

$(DEV_STAMP): requirements-dev.txt $(RUNTIME_STAMP)
	$(PY) -m pip install --quiet --disable-pip-version-check -r requirements-dev.txt
	touch $@

demo: $(RUNTIME_STAMP)
	ROS_DOMAIN_ID=$(DOMAIN) $(VENV)/bin/uav_fusion demo $(DEMO_ARGS)

test: $(DEV_STAMP)
	ROS_DOMAIN_ID=$(DOMAIN) $(PY) -m pytest -q $(PYTEST_ARGS)

# The property tests of test/property with many more random examples (minutes; not in CI).
# UAV_FUZZ_EXAMPLES sets the examples per test (default 10000), UAV_FUZZ_NODE_EXAMPLES those of
# the in-process fusion node test (default 200).
fuzz: $(DEV_STAMP)
	ROS_DOMAIN_ID=$(DOMAIN) UAV_FUZZ=1 $(PY) -m pytest -v -p no:cacheprovider --timeout=0 \
		--hypothesis-show-statistics test/property $(PYTEST_ARGS)

# mypy: the package and the tests (pyproject.toml), then the two conftest files it leaves out
lint: $(DEV_STAMP)
	$(VENV)/bin/ruff check uav_fusion test scripts
	$(VENV)/bin/mypy
	$(VENV)/bin/mypy test/faults/conftest.py
	$(VENV)/bin/mypy test/property/conftest.py
	$(VENV)/bin/lint-imports

bench: $(DEV_STAMP)
	ROS_DOMAIN_ID=$(DOMAIN) $(PY) scripts/bench_filter.py

# the accuracy benchmark's test half (docs/benchmark.md); BENCH_ARGS e.g. "--profiles paper tracker"
bench-accuracy: $(RUNTIME_STAMP)
	$(VENV)/bin/uav_fusion bench $(BENCH_ARGS)

# fusion_node against a bare rclpy relay (own processes, own domain above 100)
bench-node: $(DEV_STAMP)
	$(PY) scripts/bench_node.py $(BENCH_ARGS)

# sweep engine scaling: 2 Dask workers vs 1, and Dask's overhead vs a plain loop
bench-sweep: $(RUNTIME_STAMP)
	$(PY) scripts/bench_sweep.py

# the node graph under load: lossless in-process speed, then separate processes at rising
# replay rates until messages are lost (docs/faults.md); BENCH_ARGS e.g. "--rates 25 50 100"
bench-load: $(RUNTIME_STAMP)
	ROS_DOMAIN_ID=$(DOMAIN) $(PY) scripts/load_test.py $(BENCH_ARGS)

# the graph across three hosts (unprivileged network namespaces; docs/deploy.md);
# BENCH_ARGS e.g. "--rate 20 --rf-outage 10 --outage-after 15"
bench-multihost: $(RUNTIME_STAMP)
	$(PY) scripts/multihost.py $(BENCH_ARGS)

# the paper profile on the twin's stress plans: what its largest radar track follows, the
# radar reports it keeps and the fused error (docs/twin.md)
bench-stress: $(RUNTIME_STAMP)
	$(PY) scripts/twin_stress.py $(BENCH_ARGS)

clean:
	rm -rf build install log out .pytest_cache .mypy_cache .ruff_cache
