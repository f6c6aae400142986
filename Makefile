# Two commands do everything on a fresh machine: `make run` and `make test`.
# Both create or refresh .venv when pyproject.toml changed, then run.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
OUT ?= out
SHARED_DATA := $(abspath ../shared/datasets)
# Data is found through SONARSLAM_DATA; point it at ../shared/datasets when that exists.
export SONARSLAM_DATA ?= $(if $(wildcard $(SHARED_DATA)/marina),$(SHARED_DATA),)
export MPLBACKEND := Agg

.PHONY: venv run test lint bench clean help

help:
	@echo "make run    set up .venv and run the main job (best closed loop; marina if SONARSLAM_DATA has it)"
	@echo "make test   set up .venv, lint (ruff, mypy) and run the tests"
	@echo "make bench  speed benchmarks (benchmarks/)"

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --disable-pip-version-check -e '.[dev]'
	touch $(STAMP)

venv: $(STAMP)

run: $(STAMP)
	$(BIN)/sonarslam demo --out $(OUT)

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check sonar features slam datasets tests benchmarks
	$(BIN)/mypy

test: lint
	$(BIN)/python -m pytest -q -n 2 -rs --durations=10

bench: $(STAMP)
	$(BIN)/python benchmarks/run_benchmarks.py

clean:
	rm -rf $(OUT) .pytest_cache .mypy_cache .ruff_cache
