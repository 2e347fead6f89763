# Both targets do all set-up themselves (scripts/setup.sh is idempotent and fast when nothing changed).
SHELL := /bin/bash
VENV := .venv
export AMENT_PREFIX_PATH := $(CURDIR)/$(VENV)
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST

.PHONY: setup demo test bench clean

setup:
	@bash scripts/setup.sh

demo: setup
	@$(VENV)/bin/python scripts/demo.py

test: setup
	@$(VENV)/bin/python -m pytest $(PYTEST_ARGS)

clean:
	rm -rf $(VENV) build install log
