# Two commands on a fresh machine: `make demo` and `make test` (each sets up first).
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: setup browser demo test test-slow test-variants bench schema clean

setup: $(STAMP) browser

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	# torch first: 2.13.0 is a CPU build; any other version pulls gigabytes of CUDA packages
	$(PY) -m pip install -q torch==2.13.0
	# ray: the RLlib backend (its tests run in `make test`); 1-2 minutes more than train and dev alone; mujoco: physics specs;
	# dmc: dm_control, which the DeepMind Control parity tests step
	$(PY) -m pip install -q -e ".[train,dev,ray,mujoco,dmc]"
	touch $(STAMP)

browser: $(STAMP)  ## the headless Chromium of the viewer's browser tests, with npm, into ~/.cache/visualenv (a note, no error, without node)
	$(PY) tests/fixtures/chromium.py

demo: setup  ## build a bundled spec and show its result
	$(VENV)/bin/visualenv build specs/visual_cartpole.yaml

test: setup  ## format check and lint (ruff), type-check (mypy), then run the test suite (all but the `slow` end-to-end runs and costlier comparisons: 12-14 min on 2 cores)
	$(VENV)/bin/ruff format --check visualenv tests
	$(VENV)/bin/ruff check .
	$(VENV)/bin/mypy
	$(PY) -m pytest -m "not slow"

test-slow: setup  ## the `slow` end-to-end runs: training, the shipped agents' replays, Ray clusters, soaks (CI runs them after `make test`)
	$(PY) -m pytest -m slow

test-variants: setup  ## the suite on one core and under other CPU dispatch (docs/testing.md)
	taskset -c 0 $(PY) -m pytest -q
	ONEDNN_MAX_CPU_ISA=AVX2 $(PY) -m pytest -q
	if grep -qw avx512f /proc/cpuinfo; then ONEDNN_MAX_CPU_ISA=AVX512_CORE $(PY) -m pytest -q; else echo "no AVX-512 here: that variant skipped"; fi
	MKL_CBWR=COMPATIBLE $(PY) -m pytest -q

bench: setup
	$(VENV)/bin/visualenv bench specs/visual_cartpole.yaml

schema: setup
	$(VENV)/bin/visualenv schema > schemas/visualenv.schema.json

clean:
	rm -rf build runs frames .pytest_cache
