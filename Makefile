# make demo: set up .venv; the shipped GNN beside greedy and the expert on procedural cities (+ GIF).
# make demo TASK=exploration: the same on the exploration task.
# make test: set up .venv and run the test suite.
PYTHON ?= python3
TASK ?= coverage
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-$(shell cat pyproject.toml constraints.txt | cksum | cut -d' ' -f1)

.PHONY: demo test bench lint clean

$(STAMP): pyproject.toml constraints.txt
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --disable-pip-version-check -c constraints.txt -e ".[fast,expert,train,render,dev]"
	rm -f $(VENV)/.installed-*
	touch $(STAMP)

demo: $(STAMP)
	$(PY) scripts/demo.py --task $(TASK)

test: $(STAMP)
	$(PY) -m pytest

bench: $(STAMP)
	$(PY) scripts/bench_env.py

lint: $(STAMP)
	$(PY) -m ruff check marl_cover agents scripts tests
	$(PY) -m ruff format --check marl_cover agents scripts tests
	$(PY) -m mypy

clean:
	rm -rf $(VENV) outputs .pytest_cache .hypothesis .mypy_cache
