# make demo: set up .venv; the shipped GNN beside greedy and the expert on procedural cities (+ GIF).
# make demo TASK=exploration: the same on the exploration task.
# make test: set up .venv and run the test suite.
# make docs: build the documentation site (site/).
PYTHON ?= python3
TASK ?= coverage
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-$(shell cat pyproject.toml constraints.txt | cksum | cut -d' ' -f1)

.PHONY: demo test bench docs lint dist clean

$(STAMP): pyproject.toml constraints.txt
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --disable-pip-version-check -c constraints.txt -e ".[fast,expert,train,render,ray,dev]"
	rm -f $(VENV)/.installed-*
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/marl-cover demo --task $(TASK)

test: $(STAMP)
	$(PY) -m pytest

bench: $(STAMP)
	$(VENV)/bin/marl-cover bench

docs: $(STAMP)
	$(VENV)/bin/mkdocs build --strict

lint: $(STAMP)
	$(PY) -m ruff check marl_cover agents configs scripts tests
	$(PY) -m ruff format --check marl_cover agents configs scripts tests
	$(PY) tests/typecheck.py

dist: $(STAMP)
	rm -rf dist
	$(PY) -m build --no-isolation
	$(PY) -m twine check --strict dist/*

clean:
	rm -rf $(VENV) outputs site dist build .pytest_cache .hypothesis .mypy_cache
