# Fresh machine with only Python: `make demo` sets up and runs the main job, `make test` sets up and runs the tests.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: setup demo test test-fast lint bench clean

setup: $(STAMP)

$(STAMP): pyproject.toml Makefile
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet torch==2.13.0
	$(PY) -m pip install --quiet -e ".[dev,bench,viz,rl]"
	touch $(STAMP)

# Main job on built-in defaults: simulate a grouped crowd, export the dataset and a rerun recording.
demo: setup
	$(VENV)/bin/crowdsim demo --out out/demo

# The whole suite, slow tests included (CI runs exactly this).
test: setup
	$(VENV)/bin/ruff check .
	$(PY) -m pytest -n 2 --dist loadgroup

test-fast: setup
	$(PY) -m pytest -n 2 -m "not slow"

lint: setup
	$(VENV)/bin/ruff check .

bench: setup
	$(PY) bench/bench_crowdsim.py
	$(PY) bench/bench_planner.py --quick

clean:
	rm -rf $(VENV) out .pytest_cache .ruff_cache
