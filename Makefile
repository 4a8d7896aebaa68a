# ema_casadi — make demo | make test (ruff, then pytest) | make docs | make bench | make lock
# Every target creates or refreshes .venv and installs the package (editable) into it, at the
# versions of requirements/lock.txt (the exact releases the test suite was run with).
# `make lock` rewrites that file from a fresh venv holding the newest releases (then run
# `make test` and commit the lock); `make test-newest` runs the suite against the newest
# releases without the lock, in .venv-newest.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
LOCK   := requirements/lock.txt
OUT    ?= out

.PHONY: install demo test test-all test-newest docs bench lock clean

$(STAMP): pyproject.toml $(LOCK)
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -c $(LOCK) -e ".[dev]"
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/ema demo --out $(OUT)

test: $(STAMP)
	$(BIN)/ruff check ema_casadi tests benchmarks studies examples docs
	$(BIN)/python -m pytest -q -n 2 --durations=10

test-all: $(STAMP)
	$(BIN)/python -m pytest -q -n 2 -m "slow or not slow"

# the suite on the newest releases (no lock): what a user installing today gets
test-newest:
	rm -rf .venv-newest
	$(PYTHON) -m venv .venv-newest
	.venv-newest/bin/python -m pip install --quiet --upgrade pip
	.venv-newest/bin/python -m pip install --quiet -e ".[dev]"
	.venv-newest/bin/python -m pip freeze --exclude-editable | grep -iE '^(casadi|numpy|scipy|control|matplotlib)=='
	.venv-newest/bin/python -m pytest -q -n 2

# the documentation site -> docs/_build/html; warnings are errors, the gallery runs
DOCS_STAMP := $(VENV)/.docs-stamp
$(DOCS_STAMP): $(STAMP) pyproject.toml
	$(BIN)/python -m pip install --quiet -c $(LOCK) -e ".[dev,docs]"
	touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	$(BIN)/python -m sphinx -W --keep-going -b html -d docs/_build/doctrees docs docs/_build/html

bench: $(STAMP)
	$(BIN)/python benchmarks/run_all.py

# the lock from a fresh venv with the newest releases of every dependency (dev and docs extras)
lock:
	rm -rf .venv-lock
	$(PYTHON) -m venv .venv-lock
	.venv-lock/bin/python -m pip install --quiet --upgrade pip
	.venv-lock/bin/python -m pip install --quiet -e ".[dev,docs]"
	mkdir -p requirements
	{ echo "# pip freeze of a fresh venv with ema_casadi[dev,docs] (make lock); make install uses it as constraints"; \
	  .venv-lock/bin/python -m pip freeze --exclude-editable; } > $(LOCK)
	rm -rf .venv-lock

clean:
	rm -rf $(OUT) .pytest_cache build *.egg-info docs/_build docs/auto_examples docs/api/generated .venv-newest .venv-lock
