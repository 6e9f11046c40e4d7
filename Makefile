# Two Blender LTS lines, one virtual environment each (see requirements/).
#   make demo   - set up .venv (Blender 4.5 line) and bake the Cornell box headless
#   make test   - set up both environments and run the suite on both lines
SHELL := /bin/bash
find_python = $(shell for p in $$(command -v $(1) 2>/dev/null) $$(ls -d $$(pyenv root 2>/dev/null)/versions/$(2)*/bin/$(1) 2>/dev/null | sort -V -r); do "$$p" -c 'import sys' >/dev/null 2>&1 && { echo "$$p"; break; }; done)
PY311 ?= $(call find_python,python3.11,3.11)
PY313 ?= $(call find_python,python3.13,3.13)
VENV45 := .venv
VENV52 := .venv-5.2
export BLENDER_USER_RESOURCES ?= $(CURDIR)/.cache/blender-user
PYTEST_ARGS ?=
DEMO_OUT ?= build/demo

.PHONY: demo test test-4.5 test-5.2 bench bench-full clean env

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

env: $(VENV45)/.installed

demo: $(VENV45)/.installed
	NUMBA_CACHE_DIR=$(CURDIR)/.cache/numba-4.5 $(VENV45)/bin/python -m detp_bake bake sample_scenes/cornell_box.blend \
		--estimator disc_index --photons 2000000 --resolution 128 --out $(DEMO_OUT) --format exr,png \
		--apply --save $(DEMO_OUT)/cornell_box_baked.blend

test-4.5: $(VENV45)/.installed
	NUMBA_CACHE_DIR=$(CURDIR)/.cache/numba-4.5 $(VENV45)/bin/python -m pytest tests $(PYTEST_ARGS)

test-5.2:
	@if [ -z "$(PY313)" ]; then \
		echo "!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!"; \
		echo "!! Python 3.13 not found: the Blender 5.2 LTS line is NOT tested on this machine"; \
		echo "!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!"; \
		if [ "$${CI:-}" = "true" ]; then exit 1; fi; \
	else \
		$(MAKE) --no-print-directory $(VENV52)/.installed && \
		NUMBA_CACHE_DIR=$(CURDIR)/.cache/numba-5.2 $(VENV52)/bin/python -m pytest tests $(PYTEST_ARGS); \
	fi

test: test-4.5 test-5.2

clean:
	rm -rf build dist .cache .pytest_cache
