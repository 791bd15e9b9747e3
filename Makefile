# `make run` and `make test` work on a fresh machine with only python3: the first use creates .venv and
# installs gaitbench into it (again whenever pyproject.toml changes).

PYTHON ?= python3
VENV := .venv
INSTALLED := $(VENV)/.installed

.PHONY: run test lint mutation

# The main job: the demo suite (suites/demo.toml: the four terrains walked whole at N = 30, OP-DC and OP-DM: 8 walks
# solved and verified), its result table and the path of its HTML report, in about a minute on 2 cores. The store is
# results/demo and the report reports/demo/, both ignored by git; --resume makes a second `make run` reuse the
# stored walks and write the report again.
run: $(INSTALLED)
	OPENBLAS_NUM_THREADS=1 $(VENV)/bin/gaitbench run suites/demo.toml --jobs 2 --resume

test: $(INSTALLED)
	OPENBLAS_NUM_THREADS=1 $(VENV)/bin/pytest -q -n auto  # a test process per core (pytest-xdist); one BLAS thread each

# Which hand-made mistakes in the figures' code the fast tests catch (benchmarks/mutation.py; --full: every test).
mutation: $(INSTALLED)
	OPENBLAS_NUM_THREADS=1 $(VENV)/bin/python benchmarks/mutation.py

lint: $(INSTALLED)
	$(VENV)/bin/ruff check .

$(INSTALLED): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/pip install -e ".[dev]"
	touch $@
