# The two commands a newcomer needs: `make demo` and `make test`.
# The venv's interpreter: the distribution's own Python (>= 3.10, with venv) where there is
# one, else the first python3 on PATH. Debian's and Ubuntu's are built with PGO and LTO and
# linked statically, and run the agent's tick about a sixth faster than a default source
# build with a shared libpython (pyenv's): docs/performance.md, "The interpreter".
# `make PYTHON=... test` chooses another.
PYTHON ?= $(firstword $(foreach p,/usr/bin/python3 python3,$(shell $(p) -c \
	'import sys, venv, ensurepip; assert sys.version_info >= (3, 10)' 2>/dev/null && echo $(p))) python3)
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo sim test bench clean system-packages

# Debian packages for the tests of the real socketcan path (User-Mode Linux guest with vcan),
# candump, and nft for link faults between hosts; installed when missing if we are root with
# apt-get, otherwise those tests skip
# and say why.
SYSTEM_TOOLS := linux insmod candump nft
system-packages:
	@missing=0; for t in $(SYSTEM_TOOLS); do command -v $$t >/dev/null || missing=1; done; \
	if [ $$missing = 1 ]; then \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	    echo "installing user-mode-linux kmod can-utils nftables (Debian)"; \
	    apt-get update -qq && apt-get install -y -qq user-mode-linux kmod can-utils nftables >/dev/null \
	      || echo "note: could not install UML; socketcan tests will skip"; \
	  else echo "note: UML/can-utils missing and not root; socketcan tests will skip"; fi; \
	fi

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[test]'
	# MAVProxy for the ground-station acceptance tests; --no-deps: its own dependencies are
	# 3D-map and camera packages (vtk, opencv: ~780 MB) that its console modules do not use
	$(BIN)/pip install --quiet --no-deps 'MAVProxy>=1.8.75'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/boundswarm sitl scenarios/paper.toml --robot robots/ideal.toml --out runs/paper

sim: $(STAMP)
	$(BIN)/boundswarm sim scenarios/paper.toml --out runs/paper-sim

test: $(STAMP) system-packages
	-PYTHONPATH=tests $(BIN)/python -m tooling.uml ensure
	$(BIN)/ruff check .
	$(BIN)/mypy
	$(BIN)/python -m pytest

bench: $(STAMP)
	$(BIN)/python bench/batch_scaling.py

clean:
	rm -rf $(VENV) runs
