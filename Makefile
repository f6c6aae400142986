# Two commands do everything on a fresh machine: `make run` and `make test`.
# Both create or refresh .venv first. `make run` installs the runtime dependencies only (what
# `pip install .` gives: the demo needs no extra); `make test`, `make lint` and `make venv` add
# the development tools and every optional extra (.[dev]: pytest, ruff, mypy, jupyter for the
# notebooks, scikit-image; .[sim]: shapely for the drawn worlds; .[sweep]: dask, distributed).
# .venv is rebuilt only when $(PYTHON)'s version (implementation and major.minor: what its
# wheels are built for) differs from the one it was made with (make test PYTHON=python3.13),
# not when the same version sits at another path; it is reinstalled when pyproject.toml or
# requirements.lock changed. The exact versions installed are requirements.lock's (pip
# constraints).
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP_RUN := $(VENV)/.installed-run
STAMP_DEV := $(VENV)/.installed-dev
LOCK := requirements.lock
OUT ?= out
SHARED_DATA := $(abspath ../shared/datasets)
# Data is found through SONARSLAM_DATA; point it at ../shared/datasets when that exists.
export SONARSLAM_DATA ?= $(if $(wildcard $(SHARED_DATA)/marina),$(SHARED_DATA),)
export MPLBACKEND := Agg
PY_VERSION = import sys; print(sys.implementation.name, "%d.%d" % sys.version_info[:2])
# uv installs the locked versions in parallel and keeps them in its cache (~/.cache/uv): a fresh
# clone's .venv in ~25 s once that cache is warm (pip: ~3 min, it downloads every wheel again);
# pip does it when uv cannot be had. uv's own version is pinned here.
UV_VERSION := 0.13.8
PIP_QUIET := --quiet --disable-pip-version-check
define install
	{ $(BIN)/python -m pip install $(PIP_QUIET) uv==$(UV_VERSION) >/dev/null 2>&1 && \
	  $(BIN)/uv pip install --quiet --python $(BIN)/python -c $(LOCK) $(1); } || \
	$(BIN)/python -m pip install $(PIP_QUIET) -c $(LOCK) $(1)
endef

.PHONY: venv run test lint style bench lock clean help readme-figures FORCE

help:
	@echo "make run    set up .venv (runtime only) and run the main job: dead reckoning, EKF and iSAM2"
	@echo "            on the marina if SONARSLAM_DATA has it, else on a simulated harbour (it says so)"
	@echo "make test   set up .venv with the development tools, ruff, run the tests (mypy among them)"
	@echo "make venv   .venv with the development tools, without running anything"
	@echo "make bench  speed benchmarks (benchmarks/)"
	@echo "make readme-figures  re-measure the README's and docs/' generated figures (the marina)"
	@echo "make lock   re-resolve requirements.lock from pyproject.toml's ranges"
	@echo "PYTHON=python3.13 make test: the same with another interpreter (3.11 to 3.13)"

# .venv/.python holds the version the venv was made with; another version of $(PYTHON), or a
# venv whose interpreter no longer runs, rebuilds it (the same version elsewhere does not)
$(VENV)/.python: FORCE
	@want="$$($(PYTHON) -c '$(PY_VERSION)')" || { echo "$(PYTHON) not found"; exit 1; }; \
	have="$$(test -x $(BIN)/python && $(BIN)/python -c '$(PY_VERSION)' 2>/dev/null)"; \
	if [ "$$want" != "$$have" ]; then \
		if [ -n "$$have" ]; then echo "$(VENV) was made with $$have, rebuilding it with $$want ($(PYTHON))"; fi; \
		rm -rf $(VENV) && $(PYTHON) -m venv $(VENV) && echo "$$want" > $@; \
	elif [ "$$(cat $@ 2>/dev/null)" != "$$want" ]; then echo "$$want" > $@; fi

$(STAMP_RUN): pyproject.toml $(LOCK) $(VENV)/.python
	$(call install,-e .)
	touch $(STAMP_RUN)

# the development install holds the runtime one: both stamps
$(STAMP_DEV): pyproject.toml $(LOCK) $(VENV)/.python
	$(call install,-e '.[dev]')
	touch $(STAMP_RUN) $(STAMP_DEV)

venv: $(STAMP_DEV)

run: $(STAMP_RUN)
	$(BIN)/sonarslam demo --out $(OUT)

# the project's own folders only: a user's scratch .py in the clone is not the project's
LINT_DIRS = sonarslam sonar features slam datasets tests benchmarks
lint: style
	$(BIN)/mypy

style: $(STAMP_DEV)
	$(BIN)/ruff check $(LINT_DIRS) docs
	$(BIN)/ruff format --check $(LINT_DIRS)

# 2 workers on 2 cores, one BLAS thread each (more only contend); worksteal: a worker that runs
# out of tests takes them from the other, so the long tests do not decide the end
# the type check runs inside the suite (tests/test_typing.py), beside the other tests on the
# second core, rather than alone before them
test: style
	OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 \
		$(BIN)/python -m pytest -q -n 2 --dist worksteal -rs --durations=15

bench: $(STAMP_DEV)
	$(BIN)/python benchmarks/run_benchmarks.py

# the README's and docs/' generated figures: measured on the marina into docs/figures.json,
# then rendered into the pages (about 2 min; --check and --render: benchmarks/readme_figures.py)
readme-figures: $(STAMP_DEV)
	$(BIN)/python benchmarks/readme_figures.py

lock: $(STAMP_DEV)
	$(BIN)/python -m pip install --quiet --disable-pip-version-check --dry-run --ignore-installed \
		--report $(VENV)/resolved.json -e '.[dev]'
	$(BIN)/python -c 'import json, sys; r = json.load(open(sys.argv[1])); \
		rows = sorted(f"{i[\"metadata\"][\"name\"].lower()}=={i[\"metadata\"][\"version\"]}" \
		for i in r["install"] if i["metadata"]["name"] != "sonarslam"); \
		head = [l for l in open("$(LOCK)") if l.startswith("#")]; \
		open("$(LOCK)", "w").write("".join(head) + "\n".join(rows) + "\n")' $(VENV)/resolved.json

clean:
	rm -rf $(OUT) .pytest_cache .mypy_cache .ruff_cache
