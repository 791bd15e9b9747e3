# `make run` and `make test` work on a fresh machine with only python3: the first use creates .venv and
# installs gaitbench into it (again whenever pyproject.toml changes).

PYTHON ?= python3
VENV := .venv
INSTALLED := $(VENV)/.installed

.PHONY: run test lint

run: $(INSTALLED)
	$(VENV)/bin/gaitbench experiments show forward

test: $(INSTALLED)
	OPENBLAS_NUM_THREADS=1 $(VENV)/bin/pytest -q  # threaded BLAS thrashes small dense solves on 2 cores

lint: $(INSTALLED)
	$(VENV)/bin/ruff check .

$(INSTALLED): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/pip install -e ".[dev]"
	touch $@
