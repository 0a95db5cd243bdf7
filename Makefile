# Two set-up commands, both idempotent on a fresh machine with python3, make and gcc:
#   make demo   create .venv, install mrpctl (its runtime dependencies only), run the paper example, reproduce
#               the paper's figures and fly the shipped nadir-pointing scenario (results/pointing_nadir.png)
#   make test   create .venv, install mrpctl with its test extras, ruff + mypy, then the whole suite (figures
#               compared with their baseline images) and doctests
VENV ?= .venv
PYTHON := $(VENV)/bin/python
STAMP := $(VENV)/.mrpctl-installed
TEST_STAMP := $(VENV)/.mrpctl-test-installed

.PHONY: demo test check lint typecheck bench clean docs wheel-check catalogue

$(PYTHON):
	python3 -m venv $(VENV)

$(STAMP): pyproject.toml | $(PYTHON)
	$(PYTHON) -m pip install --quiet --disable-pip-version-check -e .
	touch $(STAMP)

$(TEST_STAMP): $(STAMP)
	$(PYTHON) -m pip install --quiet --disable-pip-version-check -e '.[test]'
	touch $(TEST_STAMP)

demo: $(STAMP)
	$(VENV)/bin/mrpctl example
	$(VENV)/bin/mrpctl reproduce --out results --overwrite
	$(VENV)/bin/mrpctl simulate nadir --pointing-plot results/pointing_nadir.png

# One BLAS thread per xdist worker: two workers on two cores, no oversubscription.
BLAS1 := OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1

# The whole check: lint, types, then the suite with the doctests of the package.
test: check
	$(BLAS1) $(PYTHON) -m pytest -q -n 2 --dist loadgroup --mpl --doctest-modules mrpctl tests

check: lint typecheck

lint: $(TEST_STAMP)
	$(VENV)/bin/ruff check mrpctl tests examples bench
	$(VENV)/bin/ruff format --check mrpctl tests examples bench

typecheck: $(TEST_STAMP)
	$(VENV)/bin/mypy

bench: $(STAMP)
	$(PYTHON) bench/design.py
	$(PYTHON) bench/simulate.py

clean:
	rm -rf $(VENV) results build dist site *.egg-info .pytest_cache .mypy_cache .ruff_cache

# The documentation site (mkdocs-material + mkdocstrings) into site/, warnings are errors.
docs: $(TEST_STAMP)
	$(VENV)/bin/mkdocs build --strict --site-dir site

# The wheel installed into a fresh venv outside the source tree; `python -m mrpctl --help` runs from it.
wheel-check: $(TEST_STAMP)
	$(BLAS1) MRPCTL_WHEEL_TEST=1 $(PYTHON) -m pytest -q -p no:xdist tests/test_package.py

# The hostile-input catalogue (tests/test_catalogue.py): about 100 cases, each a subprocess with a timeout and a
# memory cap; with it the store's two-writer race at 40 attempts (6 in make test); minutes, so not part of make test.
catalogue: $(TEST_STAMP)
	$(BLAS1) MRPCTL_CATALOGUE=1 MRPCTL_STRESS=1 $(PYTHON) -m pytest -q -n 2 tests/test_catalogue.py tests/test_campaign_integrity.py
