# Quick start: `make demo` compiles the grey kernels once and runs dmtrack on the sample sequence shipped in data/;
# `make test` runs the linter and the test suite (with the learned features: torch 2.13.0 CPU).
# `make docs` builds the documentation site into site/ (MkDocs, strict: a broken link or docstring fails it).
# Each creates .venv and installs what it needs.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   ?= .venv
BIN    := $(VENV)/bin
SAMPLE := data/7scenes-redkitchen-0000-0299
OUT    ?= out/demo

.PHONY: demo test lint docs bench clean

$(BIN)/python:
	$(PYTHON) -c 'import sys; assert sys.version_info >= (3, 11), "dmtrack needs Python >= 3.11, got " + sys.version'
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(VENV)/.installed: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e .
	touch $@

$(VENV)/.installed-dev: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e ".[dev,learned]" "kornia>=0.7"  # kornia: DISK cross-check only; torch stays pinned
	touch $(VENV)/.installed $@

$(VENV)/.installed-docs: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e ".[docs]"
	touch $(VENV)/.installed $@

demo: $(VENV)/.installed
	$(BIN)/dmtrack info $(SAMPLE)
	$(BIN)/dmtrack warmup --feature gray  # numba compiles once into its cache; the run then shows its steady speed
	$(BIN)/dmtrack run $(SAMPLE) --feature gray --out $(OUT)

test: $(VENV)/.installed-dev
	$(BIN)/ruff check src tests benchmarks
	$(BIN)/python -m pytest -q

lint: $(VENV)/.installed-dev
	$(BIN)/ruff check src tests benchmarks

docs: $(VENV)/.installed-docs
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --quiet

clean:
	rm -rf $(VENV) out site .pytest_cache .ruff_cache
