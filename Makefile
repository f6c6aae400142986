# Two commands do everything on a fresh machine: `make run` and `make test`.
# Both create or refresh .venv first: it is rebuilt when it was made by another interpreter than
# $(PYTHON) (make test PYTHON=python3.13), and reinstalled when pyproject.toml or requirements.lock
# changed. The exact versions installed are requirements.lock's (pip constraints).
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
LOCK := requirements.lock
OUT ?= out
SHARED_DATA := $(abspath ../shared/datasets)
# Data is found through SONARSLAM_DATA; point it at ../shared/datasets when that exists.
export SONARSLAM_DATA ?= $(if $(wildcard $(SHARED_DATA)/marina),$(SHARED_DATA),)
export MPLBACKEND := Agg
PY_VERSION = import sys; print(sys.implementation.name, "%d.%d.%d" % sys.version_info[:3])

.PHONY: venv run test lint bench lock clean help FORCE

help:
	@echo "make run    set up .venv and run the main job (best closed loop; marina if SONARSLAM_DATA has it)"
	@echo "make test   set up .venv, lint (ruff, mypy) and run the tests"
	@echo "make bench  speed benchmarks (benchmarks/)"
	@echo "make lock   re-resolve requirements.lock from pyproject.toml's ranges"
	@echo "PYTHON=python3.13 make test: the same with another interpreter (3.11 to 3.13)"

# .venv/.python holds the interpreter the venv was made with; a different $(PYTHON) rebuilds it
$(VENV)/.python: FORCE
	@want="$$($(PYTHON) -c '$(PY_VERSION)')" || { echo "$(PYTHON) not found"; exit 1; }; \
	have="$$(test -x $(BIN)/python && $(BIN)/python -c '$(PY_VERSION)')"; \
	if [ "$$want" != "$$have" ]; then \
		if [ -n "$$have" ]; then echo "$(VENV) was made with $$have, rebuilding it with $$want ($(PYTHON))"; fi; \
		rm -rf $(VENV) && $(PYTHON) -m venv $(VENV) && echo "$$want" > $@; \
	elif [ "$$(cat $@ 2>/dev/null)" != "$$want" ]; then echo "$$want" > $@; fi

$(STAMP): pyproject.toml $(LOCK) $(VENV)/.python
	$(BIN)/python -m pip install --quiet --disable-pip-version-check -c $(LOCK) -e '.[dev]'
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

lock: $(STAMP)
	$(BIN)/python -m pip install --quiet --disable-pip-version-check --dry-run --ignore-installed \
		--report $(VENV)/resolved.json -e '.[dev]'
	$(BIN)/python -c 'import json, sys; r = json.load(open(sys.argv[1])); \
		rows = sorted(f"{i[\"metadata\"][\"name\"].lower()}=={i[\"metadata\"][\"version\"]}" \
		for i in r["install"] if i["metadata"]["name"] != "sonarslam"); \
		head = [l for l in open("$(LOCK)") if l.startswith("#")]; \
		open("$(LOCK)", "w").write("".join(head) + "\n".join(rows) + "\n")' $(VENV)/resolved.json

clean:
	rm -rf $(OUT) .pytest_cache .mypy_cache .ruff_cache
