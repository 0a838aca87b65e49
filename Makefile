# Fresh machine with only Python: `make demo` sets up and runs the main job, `make test` sets up and runs the tests.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: setup demo demo-crowd test test-fast lint bench soak benchmark synthetic-predictor clean

setup: $(STAMP)

$(STAMP): pyproject.toml Makefile
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet torch==2.13.0
	$(PY) -m pip install --quiet -e ".[dev,bench,rl,ray,video]"
	# ORCA (the crowdnav-classic/-plusplus suites): without its declared ir-sim, which it never imports (README)
	$(PY) -m pip install --quiet --no-deps pyrvo==0.4.3
	touch $(STAMP)

# Main job on built-in defaults: a grouped crowd, GP-Graph prediction and the MPC robot end to end; writes the
# metrics (demo.json/.md), demo.png and a rerun recording demo.rrd to out/demo.
demo: setup
	$(VENV)/bin/crowdnav demo --out out/demo
	@echo "The console scripts (crowdsim, gpgraph, crowdnav, rerun) are in $(VENV)/bin: run 'source $(VENV)/bin/activate' first (README, A tour in five commands)."

# The crowd simulator alone: simulate a grouped crowd, export the dataset and a rerun recording.
demo-crowd: setup
	$(VENV)/bin/crowdsim demo --out out/demo-crowd

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
	$(PY) bench/bench_env.py --quick
	$(PY) bench/bench_shield.py --steps 100

# Soak tests (BENCHMARKS.md "Soak"): 10^4 env steps per policy, 10^3 resets, a 30-minute 400-person crowd; ~15 min.
soak: setup
	$(PY) bench/soak.py

# The planner benchmark behind RESULTS.md ("Planner benchmark"): suite crowdnav-v1 v5 (5 real ETH/UCY replays x 50
# episodes, 20 synthetic cells x 10), mpc-gpgraph, mpc-cv, mpc-none, social-force and the packaged RL agent
# ppo-crowdnav, 2 workers (about 37 min). Resumable: rerun to continue a killed run. Prints the leaderboard; files in
# out/bench-v5 (2026-11-25: the 12-pedestrian MPC, the pairwise-assigner default predictor, arrivals back-filled in
# the history). Not run in CI.
benchmark: setup
	$(VENV)/bin/crowdnav benchmark --suite crowdnav-v1 --out out/bench-v6 \
		--policy mpc-gpgraph mpc-oracle mpc-oracle-paths mpc-oracle-groups mpc-cv mpc-none social-force ppo-crowdnav

# Regenerate the crowdsim data and retrain, evaluate and repackage the default synthetic predictors
# (gpgraph-stgcnn-synthetic, stgcnn-synthetic); about 1.5 h on the 2-core machine. Not run in CI. See RESULTS.md.
synthetic-predictor: setup
	bash scripts/synthetic_predictor.sh all

clean:
	rm -rf $(VENV) out .pytest_cache .ruff_cache
