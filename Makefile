# Two Blender LTS lines, one virtual environment each (see requirements/).
#   make demo   - set up .venv (Blender 4.5 line) and bake the Cornell box headless
#   make test   - set up the environments and run the suite on both lines (4.5: without bpy, then the rest)
#   make test-core - the core suite in an environment without bpy (Blender tests skip, one reason)
SHELL := /bin/bash
find_python = $(shell for p in $$(command -v $(1) 2>/dev/null) $$(ls -d $$(pyenv root 2>/dev/null)/versions/$(2)*/bin/$(1) 2>/dev/null | sort -V -r); do "$$p" -c 'import sys' >/dev/null 2>&1 && { echo "$$p"; break; }; done)
PY311 ?= $(call find_python,python3.11,3.11)
PY313 ?= $(call find_python,python3.13,3.13)
VENV45 := .venv
VENV52 := .venv-5.2
VENVCORE := .venv-core
export BLENDER_USER_RESOURCES ?= $(CURDIR)/.cache/blender-user
PYTEST_ARGS ?= --durations=25
# numba's cache checks only the date of the file that holds a kernel, not of the files whose
# helpers it inlines: a cache folder per state of the core's sources never serves stale code.
CORE_HASH := $(shell cat $$(find detp_bake -name '*.py' | sort) | cksum | cut -d' ' -f1)
DEMO_OUT ?= build/demo

.PHONY: demo test test-4.5 test-4.5-blender test-5.2 test-core bench bench-full clean env viewer viewer-node chromium

$(VENV45)/.installed: requirements/blender-4.5.txt
	@test -n "$(PY311)" || { echo "error: Python 3.11 not found (needed for the Blender 4.5 LTS line)"; exit 1; }
	"$(PY311)" -m venv $(VENV45)
	$(VENV45)/bin/python -m pip install -q --upgrade pip
	$(VENV45)/bin/python -m pip install -q -r requirements/blender-4.5.txt
	touch $@

$(VENV52)/.installed: requirements/blender-5.2.txt
	"$(PY313)" -m venv $(VENV52)
	$(VENV52)/bin/python -m pip install -q --upgrade pip
	$(VENV52)/bin/python -m pip install -q -r requirements/blender-5.2.txt
	touch $@

# The 4.5 line's pins without bpy: the core must import, and its tests pass, with no Blender at all.
$(VENVCORE)/.installed: requirements/blender-4.5.txt
	@test -n "$(PY311)" || { echo "error: Python 3.11 not found (needed for the core environment)"; exit 1; }
	"$(PY311)" -m venv $(VENVCORE)
	grep -v '^bpy==' requirements/blender-4.5.txt > $(VENVCORE)/requirements.txt
	$(VENVCORE)/bin/python -m pip install -q -r $(VENVCORE)/requirements.txt
	touch $@

# It writes the tests it skipped for want of bpy to NEEDS_BLENDER (tests/conftest.py). Its kernels go to the
# 4.5 line's numba cache (the same CPython, numba and numpy): the Blender half that follows loads them.
NEEDS_BLENDER := .cache/needs-blender.txt
test-core: $(VENVCORE)/.installed
	DETP_BAKE_NEEDS_BLENDER=$(CURDIR)/$(NEEDS_BLENDER) NUMBA_CACHE_DIR=$(CURDIR)/.cache/numba-4.5-$(CORE_HASH) \
		$(VENVCORE)/bin/python -m pytest tests -q -p no:cacheprovider $(PYTEST_ARGS)

env: $(VENV45)/.installed

demo: $(VENV45)/.installed
	NUMBA_CACHE_DIR=$(CURDIR)/.cache/numba-4.5-$(CORE_HASH) $(VENV45)/bin/python -m detp_bake bake sample_scenes/cornell_box.blend \
		--photons 4000000 --resolution 128 --out $(DEMO_OUT) --format exr,png \
		--apply --save $(DEMO_OUT)/cornell_box_baked.blend

test-4.5: $(VENV45)/.installed
	NUMBA_CACHE_DIR=$(CURDIR)/.cache/numba-4.5-$(CORE_HASH) $(VENV45)/bin/python -m pytest tests $(PYTEST_ARGS)

# The 4.5 line in `make test`: exactly the tests test-core skipped for want of bpy.
test-4.5-blender: test-core $(VENV45)/.installed viewer-node chromium
	@test -s $(NEEDS_BLENDER) || { echo "error: test-core named no Blender test ($(NEEDS_BLENDER))"; exit 1; }
	NUMBA_CACHE_DIR=$(CURDIR)/.cache/numba-4.5-$(CORE_HASH) $(VENV45)/bin/python -m pytest @$(NEEDS_BLENDER) $(PYTEST_ARGS)

test-5.2: viewer-node chromium
	@if [ -z "$(PY313)" ]; then \
		echo "!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!"; \
		echo "!! Python 3.13 not found: the Blender 5.2 LTS line is NOT tested on this machine"; \
		echo "!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!"; \
		if [ "$${CI:-}" = "true" ]; then exit 1; fi; \
	else \
		$(MAKE) --no-print-directory $(VENV52)/.installed && \
		NUMBA_CACHE_DIR=$(CURDIR)/.cache/numba-5.2-$(CORE_HASH) $(VENV52)/bin/python -m pytest tests $(PYTEST_ARGS); \
	fi

# Every test runs once on the 4.5 pins: the whole suite without bpy (test-core: the core must work
# without Blender, and a test that needs it unmarked fails there), then with bpy the tests it skipped;
# the 5.2 line runs the whole suite beside them. The suite is mostly one thread (numba's cold
# compiles, Blender's file loads), so on 2 cores the two lines take about the time of one.
OUTPUT_SYNC := $(if $(filter output-sync,$(.FEATURES)),--output-sync=target,)
test:
	$(MAKE) --no-print-directory -j2 $(OUTPUT_SYNC) test-4.5-blender test-5.2

# The web viewer (viewer/, docs/viewer.md) and its browser test (tests/test_viewer.py): three.js and
# playwright-core from package-lock.json, and Debian's chromium. Neither failing stops the build:
# the browser test then skips, saying which is missing.
VIEWER_NODE := viewer/node_modules/.installed
$(VIEWER_NODE): viewer/package-lock.json
	@if ! command -v npm >/dev/null 2>&1; then \
		echo "!! npm not found: viewer/node_modules not installed (make viewer and tests/test_viewer.py need it)"; \
	elif npm ci --prefix viewer --no-audit --no-fund --loglevel=error; then \
		touch $@; \
	else \
		echo "!! npm ci --prefix viewer failed: tests/test_viewer.py will skip"; \
	fi

viewer-node: $(VIEWER_NODE)

chromium:
	@if [ -x /usr/bin/chromium ]; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
		mkdir -p .cache && echo "installing Debian's chromium for tests/test_viewer.py (log: .cache/apt-chromium.log)"; \
		{ apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends chromium; } \
			>.cache/apt-chromium.log 2>&1 \
			|| echo "!! apt-get install chromium failed (.cache/apt-chromium.log): tests/test_viewer.py will skip"; \
	else \
		echo "!! /usr/bin/chromium not found: tests/test_viewer.py will skip (install it: sudo apt-get install chromium)"; \
	fi

# make viewer [MODEL=path/to/scene.glb] [VIEWER_PORT=8000]: serve the viewer page, its three.js files
# and the one model on 127.0.0.1 (viewer/serve.py; never the repository), and print the URL.
VIEWER_PORT ?= 8000
MODEL ?=
viewer: viewer-node
	@test -f $(VIEWER_NODE) || { echo "error: viewer/node_modules is missing (npm ci --prefix viewer)"; exit 1; }
	@exec python3 viewer/serve.py --port $(VIEWER_PORT) $(if $(MODEL),--model "$(MODEL)")

# Extension zips, one per Blender line and platform of blender_manifest.toml, each with that line's
# wheels only (cp311 for 4.5, cp313 for 5.2; numpy and OpenImageIO are Blender's own, pyoidn on Linux
# has its CPU device only):
# dist/detp_bake-<version>-blender<line>-<platform>.zip. Built by Blender's own extension tool, which
# the bpy wheel ships as a standalone script; the wheels are downloaded once into .cache/.
BLENDER_EXT = $(firstword $(wildcard $(VENV45)/lib/python3.11/site-packages/bpy/*/scripts/addons_core/bl_pkg/cli/blender_ext.py))
EXT_ID := $(shell sed -n 's/^id *= *"\(.*\)"/\1/p' blender_manifest.toml)

.PHONY: extension
extension: $(VENV45)/.installed
	@test -n "$(BLENDER_EXT)" || { echo "error: blender_ext.py not found in the bpy wheel of $(VENV45)"; exit 1; }
	rm -rf dist/$(EXT_ID)-*.zip && mkdir -p dist
	$(VENV45)/bin/python tests/extension_build.py zips dist $(BLENDER_EXT)
	@ls -l dist/$(EXT_ID)-*.zip

# Benchmarks (timings never live in tests): short runs take minutes on 2 cores, full ones hours.
BENCH_OUT ?= benchmarks/results
$(VENV45)/.bench: $(VENV45)/.installed requirements/bench.txt
	$(VENV45)/bin/python -m pip install -q -r requirements/bench.txt
	touch $@

bench: $(VENV45)/.bench
	$(VENV45)/bin/python benchmarks/trace.py --json $(BENCH_OUT)/trace.json
	$(VENV45)/bin/python benchmarks/estimators.py --photons 300000 --json $(BENCH_OUT)/estimators.json
	$(VENV45)/bin/python benchmarks/paper.py --out $(BENCH_OUT)
	$(VENV45)/bin/python benchmarks/quality.py --out $(BENCH_OUT)

bench-full: $(VENV45)/.bench
	$(VENV45)/bin/python benchmarks/trace.py --json $(BENCH_OUT)/trace.json
	$(VENV45)/bin/python benchmarks/estimators.py --json $(BENCH_OUT)/estimators.json
	$(VENV45)/bin/python benchmarks/disc_index_embree.py
	$(VENV45)/bin/python benchmarks/paper.py --full --out $(BENCH_OUT)
	$(VENV45)/bin/python benchmarks/quality.py --full --out $(BENCH_OUT)

clean:
	rm -rf build dist wheels .cache .pytest_cache
