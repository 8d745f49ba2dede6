# ema: every target creates .venv if missing and installs what it needs (idempotent).
PY      ?= python3
VENV    := .venv
BIN     := $(VENV)/bin
STAMP   := $(VENV)/.installed-run
TSTAMP  := $(VENV)/.installed-test
EMA     := $(BIN)/ema
# The locks (hashes, every platform, Python 3.11+) are what every machine installs: the tested
# set. run.lock: the runtime; test.lock: the runtime's pins plus the test and dev tools;
# build.lock: the build backend for the editable install. `make lock` rewrites them from
# pyproject.toml keeping every pin it can; `make upgrade` re-resolves to the newest versions,
# runs the tests and keeps the new locks only if they pass.
LOCKS   := requirements
UVC     := $(BIN)/uv pip compile pyproject.toml --universal --python-version 3.11 \
           --generate-hashes --no-header -q
PIPI    := $(BIN)/python -m pip install -q --require-hashes --no-deps
# Tests and benchmarks pin numba to one thread per process unless told otherwise.
export NUMBA_NUM_THREADS ?= 2

.DEFAULT_GOAL := help
.PHONY: help run test test-all bench lint reproduce reproduce-ci acceptance acceptance-ci yield-ci design-ci emps-ci duty-ci clean \
        lock upgrade compile

help:  ## list the targets
	@grep -E '^[a-z-]+:.*## ' $(MAKEFILE_LIST) | awk -F':.*## ' '{printf "  make %-14s %s\n", $$1, $$2}'

$(BIN)/python:
	$(PY) -m venv $(VENV)
	$(BIN)/python -m pip install -q --require-hashes -r $(LOCKS)/build.lock

$(STAMP): pyproject.toml $(LOCKS)/run.lock $(LOCKS)/build.lock | $(BIN)/python
	$(PIPI) -r $(LOCKS)/build.lock
	$(PIPI) -r $(LOCKS)/run.lock
	@# setuptools' lenient editable mode always prints an information banner: not for users
	PYTHONWARNINGS="ignore:Editable installation" \
	  $(BIN)/python -m pip install -q --no-deps --no-build-isolation -e .
	@rm -f $(TSTAMP)
	@touch $@

$(TSTAMP): $(LOCKS)/test.lock $(STAMP)
	$(PIPI) -r $(LOCKS)/test.lock
	@touch $@

run: $(STAMP)  ## install, compile every kernel (first run only), run the bundled default (20 deg step)
	$(BIN)/python -m ema_cli.devtools.check_imports
	$(EMA) compile
	$(EMA) simulate

compile: $(STAMP)  ## compile every kernel entry point and variant into the cache (2 processes)
	$(EMA) compile

test: $(TSTAMP)  ## lint, undeclared imports (deptry), the fast tier of the tests (2 workers)
	$(BIN)/ruff check ema_cli tests experiments
	$(BIN)/deptry ema_cli
	$(EMA) compile
	$(BIN)/python -m pytest -n auto -m "not slow"

test-all: test  ## make test, then the slow tier (cold compiles, long end-to-end checks)
	$(BIN)/python -m pytest -n auto -m slow

bench: $(TSTAMP)  ## benchmarks: kernel, compile and start-up, make test, sweep, sensitivity, tuning, yield (and on processes and Dask), duty, the identification battery (hours)
	$(BIN)/python experiments/bench_compile.py
	$(BIN)/python experiments/bench_tests.py
	$(BIN)/python experiments/bench.py
	$(BIN)/python experiments/bench_kernel_vs_wave3.py
	$(BIN)/python experiments/emps_simulation.py
	$(BIN)/python -m experiments.bench_emps_fit
	$(BIN)/python -m experiments.plant_coverage --seeds 20
	$(BIN)/python experiments/bench_startup.py
	$(BIN)/python experiments/bench_acceptance.py
	rm -rf results/bench/yield-1000
	$(BIN)/python experiments/bench_yield.py --out results/bench/yield-1000
	$(BIN)/python experiments/bench_scale.py
	$(BIN)/python experiments/bench_duty.py
	$(BIN)/python experiments/bench_identify_logs.py
	$(BIN)/python experiments/bench_idmodes.py
	$(BIN)/python -m experiments.loggen.battery --out results/battery/logs --n 20 --seed 2026 --jobs 2
	$(BIN)/python experiments/identify_battery.py --battery results/battery/logs --out results/battery/fits
	$(BIN)/python -m experiments.identify_crb --battery results/battery/logs --out results/battery/crb
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

yield-ci: $(STAMP)  ## ema yield of the reference battery at a small N, its claim (replaces results/yield-ci)
	rm -rf results/yield-ci
	$(EMA) yield configs/acceptance.yaml --tolerances configs/tolerances.yaml --n 32 --seed 0 \
	  --worst-budget 16 --min-yield 0.25 --out results/yield-ci

emps-ci: $(STAMP)  ## ema identify plant on the EMPS record, its claims (replaces results/emps-ci)
	rm -rf results/emps-ci
	$(EMA) identify plant experiments/data/emps/DATA_EMPS.mat --actuator configs/actuators/emps.yaml \
	  --out results/emps-ci
	$(BIN)/python -m experiments.emps_claims results/emps-ci

duty-ci: $(STAMP)  ## ema duty on the bundled 8.6 h TVC profile and its acceptance test (replaces results/duty-ci)
	rm -rf results/duty-ci
	$(EMA) duty configs/duty/tvc.yaml --out results/duty-ci/tvc
	$(EMA) acceptance configs/acceptance_duty.yaml --out results/duty-ci/acceptance

design-ci: $(STAMP)  ## ema design on the bundled log, small budget (replaces results/design-ci)
	rm -rf results/design-ci
	$(EMA) design experiments/logs/design_hc_1pct.csv configs/design_ci.yaml \
	  --spec configs/acceptance_geared.yaml --budget 192 --out results/design-ci

lock: $(TSTAMP)  ## rewrite the locks from pyproject.toml, keeping every pin that still fits
	$(UVC) -o $(LOCKS)/run.lock
	$(UVC) --extra test --extra dev -c $(LOCKS)/run.lock -o $(LOCKS)/test.lock
	@rm -f $(STAMP) $(TSTAMP)

upgrade: $(TSTAMP)  ## re-resolve to the newest versions, run the tests, keep the locks if green
	cp $(LOCKS)/run.lock $(LOCKS)/run.lock.bak && cp $(LOCKS)/test.lock $(LOCKS)/test.lock.bak
	$(UVC) --upgrade -o $(LOCKS)/run.lock
	$(UVC) --upgrade --extra test --extra dev -c $(LOCKS)/run.lock -o $(LOCKS)/test.lock
	@if $(MAKE) test; then rm -f $(LOCKS)/*.bak; echo "locks upgraded: review git diff $(LOCKS)"; \
	else mv $(LOCKS)/run.lock.bak $(LOCKS)/run.lock; mv $(LOCKS)/test.lock.bak $(LOCKS)/test.lock; \
	  rm -f $(STAMP) $(TSTAMP); $(MAKE) $(TSTAMP); echo "upgrade failed its tests: locks kept"; exit 1; fi

clean:  ## remove the virtual environment and caches (results/ is kept)
	rm -rf $(VENV) .pytest_cache .ruff_cache
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
