# SPDX-License-Identifier: GPL-3.0-or-later
# Development tasks. Nothing here writes outside the checkout except temporary folders:
# every run that imports bpy gets a throw-away Blender user folder.

PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.requirements-installed

# Blender's own extension CLI ships inside the bpy module (what `blender --command extension` runs).
BPY_SCRIPTS = $(firstword $(wildcard $(VENV)/lib/python3*/site-packages/bpy/*/scripts))
BLENDER_EXT = $(BPY_SCRIPTS)/addons_core/bl_pkg/cli/blender_ext.py
VALID_TAGS = $(BPY_SCRIPTS)/modules/_bpy_internal/extensions/tags.py
VERSION := $(shell sed -n 's/^version = "\(.*\)"/\1/p' blender_manifest.toml)
ZIP := dist/curved_reflections-$(VERSION).zip

# Runs the rest of the line with BLENDER_USER_RESOURCES in a temporary folder, removed after.
ISOLATED = user=$$(mktemp -d) && trap 'rm -rf "$$user"' EXIT && BLENDER_USER_RESOURCES="$$user"

.PHONY: venv test demo zip bench clean

venv: $(STAMP)

$(STAMP): requirements.txt
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --disable-pip-version-check --no-cache-dir -r requirements.txt
	touch $@

# Two workers, a test file each at a time (its module fixtures built once): on two cores
# the suite takes about two thirds of the time of one process.
test: venv
	$(ISOLATED) $(PY) -m pytest tests --ignore=tests/benchmarks -n 2 --dist loadfile --durations=15

demo: venv
	$(ISOLATED) $(PY) scripts/demo.py --out out/demo

zip: venv
	mkdir -p dist
	rm -f $(ZIP)
	$(PY) $(BLENDER_EXT) build --source-dir . --output-dir dist --valid-tags $(VALID_TAGS)
	$(PY) $(BLENDER_EXT) validate --valid-tags $(VALID_TAGS) $(ZIP)

bench: venv
	$(ISOLATED) $(PY) -m pytest tests/benchmarks -s

clean:
	rm -rf dist out .pytest_cache
