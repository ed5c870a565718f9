# Each target creates .venv and installs the package when it is missing or older than
# pyproject.toml. Only python3 is needed beforehand.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
# the package, with what `make figures`, `dfcoa compare` and `dfcoa tune` need (no torch)
STAMP  := $(VENV)/.installed
# and what the tests, the docs and the learning libraries need (torch's CPU build)
DEV    := $(VENV)/.installed-dev
JOBS   ?= 2

.PHONY: install test figures check-training tune bench lint docs clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[tune]'
	touch $(STAMP)

$(DEV): $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[tune,dev,dask,rl]'
	touch $(DEV)

install: $(STAMP)

test: $(DEV)
	MPLBACKEND=Agg $(BIN)/python -m pytest -q -n $(JOBS)

# The documentation site (mkdocs.yml) into site/; make test builds it with --strict too.
docs: $(DEV)
	$(BIN)/mkdocs build --strict

lint: $(DEV)
	$(BIN)/ruff check .

figures: $(STAMP)
	MPLBACKEND=Agg $(BIN)/python -m dfcoa_opt figures --out paper_figures

# The paper-scale checks (tests marked slow): the learned policy retrained from seed 0 gives
# the shipped bytes (6 min on one core of the 2-core Intel Xeon). CI does not run them.
check-training: $(DEV)
	MPLBACKEND=Agg $(BIN)/python -m pytest -q -m slow

# Every method tuned with the same budget on training seeds (docs/heldout.md): writes
# scenarios/sweeps/tuned/*.toml; the trials' runs stay in .dfcoa-cache/tune (resumable).
tune: $(STAMP)
	MPLBACKEND=Agg $(BIN)/python -m dfcoa_opt tune scenarios/sweeps/tune.toml --variant '*' \
		--out .dfcoa-cache/tune

# `make bench` also installs the benchmark-only peer (ir-sim) once.
$(VENV)/.bench-installed: $(DEV)
	$(BIN)/python -m pip install --quiet -e '.[tune,dev,dask,rl,bench]'
	touch $(VENV)/.bench-installed

# BENCH_FIGURES=0 leaves out row (f), a whole `dfcoa figures` in a fresh clone (about 20 min
# on 2 cores, docs/performance.md), the recipes' cost rows and the numba compilation row.
BENCH_FIGURES ?= 1

bench: $(VENV)/.bench-installed
	MPLBACKEND=Agg BENCH_FIGURES=$(BENCH_FIGURES) $(BIN)/python -m benchmarks.run

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache site
