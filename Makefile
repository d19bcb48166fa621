# Two commands that work on a fresh machine, each doing its own set-up:
#   make demo   - run the whole node graph on the bundled default flight and write out/demo/
#   make test   - run the test suite
SHELL := /bin/bash
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
RUNTIME_STAMP := $(VENV)/.runtime-installed
DEV_STAMP := $(VENV)/.dev-installed

# DDS discovery stays on this machine; each run picks its own domain.
export ROS_AUTOMATIC_DISCOVERY_RANGE := LOCALHOST
DOMAIN = $${ROS_DOMAIN_ID:-$$(( RANDOM % 100 + 1 ))}

.PHONY: demo test lint bench bench-node clean

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

lint: $(DEV_STAMP)
	$(VENV)/bin/ruff check uav_fusion test scripts
	$(VENV)/bin/mypy
	$(VENV)/bin/lint-imports

bench: $(DEV_STAMP)
	ROS_DOMAIN_ID=$(DOMAIN) $(PY) scripts/bench_filter.py

# fusion_node against a bare rclpy relay (own processes, own domain above 100)
bench-node: $(DEV_STAMP)
	$(PY) scripts/bench_node.py $(BENCH_ARGS)

clean:
	rm -rf build install log out .pytest_cache .mypy_cache .ruff_cache
