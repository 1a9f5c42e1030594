# Spectral Skin SSS — set-up, tests, demo, benchmarks.
# `make demo` and `make test` each create .venv when missing and install everything pinned.
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: install demo test lint bench clean

install: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	# CPU build of torch only (a local wheel on these machines); never the CUDA wheels.
	$(PY) -m pip install -q "torch==2.13.0+cpu"
	$(PY) -m pip install -q -e ".[training,blender,test]"
	touch $(STAMP)

test: $(STAMP)
	$(PY) -m pytest -q tests

lint: $(STAMP)
	$(PY) -m ruff check exporters training blender_addon tests

demo: $(STAMP)
	$(PY) -m training demo

bench: $(STAMP)
	$(PY) -m training bench --out bench/results.md

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache
