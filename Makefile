# The two commands: `make demo` and `make test`. Both set up what they need (idempotent).
VENV ?= .venv
PY := $(VENV)/bin/python
export PYOPENGL_PLATFORM ?= egl
export NO_ALBUMENTATIONS_UPDATE := 1
export AIAS_DATA ?= $(abspath ../shared/data)

.PHONY: setup demo test bench clean-out

setup:
	@bash tools/setup.sh

demo: setup
	$(PY) -m aias_augment.cli.demo --out out/demo

test: setup
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/lint-imports --no-logo --no-cache
	$(PY) -m pytest -q tests

clean-out:
	rm -rf out
