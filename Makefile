# Spectral Skin SSS — set-up, tests, demo, benchmarks, documentation.
# `make demo` and `make test` each create .venv when missing and install everything pinned.
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

MITSUBA_STAMP := $(VENV)/.mitsuba-installed
DOCS_STAMP := $(VENV)/.docs-installed

# The oldest and the newest supported Blender, as bpy modules in their own venvs (tests/test_addon_versions.py
# installs the extension zip in each).  bpy 4.2 LTS runs Python 3.11, bpy 5.1 and later 3.13.  Each bpy wheel is
# ~0.3 GB to download (~3 min here) and ~1 GB installed; numpy pinned as Blender bundles it.
PYTHON313 ?= $(firstword $(wildcard $(HOME)/.pyenv/versions/3.13*/bin/python3.13) python3.13)
BLENDER_OLDEST := .venv-blender42
BLENDER_NEWEST := .venv-blender53
BLENDER_OLDEST_STAMP := $(BLENDER_OLDEST)/.installed-bpy-4.2.23
BLENDER_NEWEST_STAMP := $(BLENDER_NEWEST)/.installed-bpy-5.3.0

.PHONY: install mitsuba blender-envs demo extension test validate lint bench docs clean

install: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	# CPU build of torch only (a local wheel on these machines); never the CUDA wheels.
	$(PY) -m pip install -q "torch==2.13.0+cpu"
	$(PY) -m pip install -q -e ".[training,blender,test,cluster,openpbr]"
	touch $(STAMP)

# Mitsuba 3 (the validation renderer): the pinned `mitsuba` extra, and libLLVM 19 for its llvm_ad_* variants
# (Dr.Jit refuses LLVM 14, and volpath renders abort with LLVM 15: notes on Mitsuba).  Debian's libllvm19
# needs root; without it only the scalar variants run (the tests skip the LLVM ones and say why).
mitsuba: $(MITSUBA_STAMP)

$(MITSUBA_STAMP): $(STAMP)
	$(PY) -m pip install -q -e ".[mitsuba]"
	@if ls /usr/lib/*/libLLVM.so.19* /usr/lib/*/libLLVM-19.so* >/dev/null 2>&1; then echo "libLLVM 19: present"; \
	elif command -v apt-get >/dev/null 2>&1 && [ "$$(id -u)" = 0 ]; then \
	  export DEBIAN_FRONTEND=noninteractive; \
	  (apt-get install -y -q libllvm19 >/dev/null || (apt-get update -q >/dev/null && apt-get install -y -q libllvm19 >/dev/null)) \
	    && echo "libLLVM 19: installed (libllvm19)" \
	    || echo "warning: could not install libllvm19; Mitsuba's scalar variants still work"; \
	else echo "warning: libllvm19 needs root and apt-get; Mitsuba's scalar variants still work"; fi
	touch $@

blender-envs: $(BLENDER_OLDEST_STAMP) $(BLENDER_NEWEST_STAMP)

$(BLENDER_OLDEST_STAMP):
	test -x $(BLENDER_OLDEST)/bin/python || $(PYTHON) -m venv $(BLENDER_OLDEST)
	$(BLENDER_OLDEST)/bin/python -m pip install -q "bpy==4.2.23" "numpy==1.26.4"
	$(BLENDER_OLDEST)/bin/python tests/blender_env.py
	touch $@

$(BLENDER_NEWEST_STAMP):
	test -x $(BLENDER_NEWEST)/bin/python || $(PYTHON313) -m venv $(BLENDER_NEWEST)
	$(BLENDER_NEWEST)/bin/python -m pip install -q "bpy==5.3.0" "numpy==2.5.5"
	$(BLENDER_NEWEST)/bin/python tests/blender_env.py
	touch $@

# Two workers (pytest-xdist), one per core, each taking whole test files (module fixtures are built once).
test: $(STAMP) $(MITSUBA_STAMP) $(BLENDER_OLDEST_STAMP) $(BLENDER_NEWEST_STAMP)
	$(PY) -m pytest -q -n 2 --dist loadfile tests

# The full physics validation that make test samples (pytest marker `validation`, docs/dev/testing.md): Mitsuba
# against our renderer, and Cycles' render of a bake against its colour, at the medium tone too (make test runs the
# lightest and the darkest).
validate: $(STAMP) $(MITSUBA_STAMP)
	$(PY) -m pytest -q -n 2 --dist loadfile -m validation tests

lint: $(STAMP)
	$(PY) -m ruff check exporters training blender_addon tests

# Then the skin edits: the medium head as painted, tanned, flushed and pale, back-lit, and a keyframed flush
# (Blood 1 -> 2.5 -> 1 over 24 frames at 80 px, 8 samples) as a strip; both figures into docs/figures/.
demo: $(STAMP)
	$(PY) -m training demo
	$(PY) -m training.demo_render --edits-row --out demo/out/edits --render-size 160 --samples 16 \
		--texture-size 256 --figure docs/figures/skin_edits_row.png
	$(PY) -m training.demo_render --flush-strip --out demo/out/flush --figure docs/figures/skin_edits_flush_strip.png
	$(PY) -m training.demo_render --mask-row --out demo/out/mask --figure docs/figures/skin_edits_mask_row.png

# Blender extension zip (dist/) for linux-x64 (onnxruntime wheels for Python 3.11 and 3.13: one zip for Blender
# 4.2 to 5.3), built and validated by Blender's own extension tool from the bpy wheel;
# PLATFORMS=linux-x64,windows-x64,macos-arm64 for more (one zip each).
PLATFORMS ?= linux-x64
extension: $(STAMP)
	$(PY) blender_addon/package.py --out dist --platforms $(PLATFORMS)

# The documentation site (docs/dev/documentation.md): Sphinx + MyST + autodoc + sphinx-argparse, warnings as
# errors; then the linkcheck builder, offline (external URLs are listed, not fetched).  DOCS_OUT=DIR for another folder.
DOCS_OUT ?= build/docs
docs: $(DOCS_STAMP)
	rm -rf docs/reference/_generated
	$(PY) -m sphinx -W --keep-going -q -b html -d $(DOCS_OUT)/doctrees docs $(DOCS_OUT)/html
	$(PY) -m sphinx -W --keep-going -q -b linkcheck -d $(DOCS_OUT)/doctrees docs $(DOCS_OUT)/linkcheck
	@echo "documentation: $(DOCS_OUT)/html/index.html"

$(DOCS_STAMP): $(STAMP)
	$(PY) -m pip install -q -e ".[docs]"
	touch $@

bench: $(STAMP)
	$(PY) -m training bench --out bench/results.md

clean:
	rm -rf $(VENV) $(BLENDER_OLDEST) $(BLENDER_NEWEST) .pytest_cache .ruff_cache build/docs docs/reference/_generated
