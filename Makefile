# ema: every target creates .venv if missing and installs what it needs (idempotent).
PY      ?= python3
VENV    := .venv
BIN     := $(VENV)/bin
STAMP   := $(VENV)/.installed-run
TSTAMP  := $(VENV)/.installed-test
EMA     := $(BIN)/ema
# Tests and benchmarks pin numba to one thread per process unless told otherwise.
export NUMBA_NUM_THREADS ?= 2

.DEFAULT_GOAL := help
.PHONY: help run test bench lint reproduce reproduce-ci acceptance acceptance-ci clean

help:  ## list the targets
	@grep -E '^[a-z-]+:.*## ' $(MAKEFILE_LIST) | awk -F':.*## ' '{printf "  make %-14s %s\n", $$1, $$2}'

$(BIN)/python:
	$(PY) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip

$(STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install -q -e .
	@touch $@

$(TSTAMP): pyproject.toml $(STAMP)
	$(BIN)/python -m pip install -q -e '.[test]'
	@touch $@

run: $(STAMP)  ## run the main job: the bundled default (20 deg step, all defaults)
	$(EMA) simulate

test: $(TSTAMP)  ## lint, then the whole test suite
	$(BIN)/ruff check ema_cli tests
	$(BIN)/python -m pytest

bench: $(STAMP)  ## benchmarks: kernel throughput, batch scaling, 1000-job sweep, start-up, sensitivity, tuning
	$(BIN)/python experiments/bench.py
	$(BIN)/python experiments/bench_startup.py
	$(BIN)/python experiments/bench_acceptance.py
	$(BIN)/python experiments/bench_identify_logs.py
	$(BIN)/python experiments/bench_sensitivity.py
	$(BIN)/python experiments/bench_tune.py

lint: $(TSTAMP)  ## ruff
	$(BIN)/ruff check ema_cli tests experiments

reproduce: $(STAMP)  ## reproduce the paper (Figs 2-10, identification, claims)
	$(EMA) reproduce experiments/paper2020.yaml

reproduce-ci: $(STAMP)  ## the same batch as CI runs it (replaces results/reproduce-ci)
	rm -rf results/reproduce-ci
	$(EMA) reproduce experiments/paper2020.yaml --out results/reproduce-ci

acceptance: $(STAMP)  ## the acceptance battery of the reference EMA (configs/acceptance.yaml)
	$(EMA) acceptance configs/acceptance.yaml

acceptance-ci: $(STAMP)  ## the same as CI runs it (replaces results/acceptance-ci)
	rm -rf results/acceptance-ci
	$(EMA) acceptance configs/acceptance.yaml --out results/acceptance-ci

clean:  ## remove the virtual environment and caches (results/ is kept)
	rm -rf $(VENV) .pytest_cache .ruff_cache
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
