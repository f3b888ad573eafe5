# Two commands on a fresh machine: `make study` and `make test`.
# Both create a virtual environment in .venv (if missing) and install the
# workbench into it in editable mode; the stamp file re-runs the install only
# when pyproject.toml changes.

PYTHON ?= python3
VENV ?= .venv
VPY := $(VENV)/bin/python
STAMP := $(VENV)/.vehid-installed

.PHONY: study test bench bench-real clean-cache setup docs

setup: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(VPY) || $(PYTHON) -m venv $(VENV)
	$(VPY) -m pip install --quiet --disable-pip-version-check -e '.[test]'
	touch $(STAMP)

study: $(STAMP)
	$(VENV)/bin/vehid study handling

test: $(STAMP)
	$(VPY) -m pytest

# The documentation site, into docs/_build/html (warnings are errors; the gallery's
# examples run in full here, on shortened records in the test suite)
docs: $(STAMP)
	$(VPY) -m sphinx -W --keep-going -b html docs docs/_build/html

bench: $(STAMP)
	$(VPY) benchmarks/run_all.py

# Hold-out fits on the public records in tests/data against peer libraries, which the
# script installs into their own environment, benchmarks/.peers-venv (never into .venv).
bench-real: $(STAMP)
	$(VPY) benchmarks/real_data.py

clean-cache:
	rm -rf $${VEHID_CACHE_DIR:-$$HOME/.cache/vehid}
