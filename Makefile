# rangeplan: `make run` and `make test` do all setup on a fresh clone.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp

# Small dense matrices: single-threaded BLAS is much faster on these machines.
export OPENBLAS_NUM_THREADS := 1
export OMP_NUM_THREADS := 1
export MKL_NUM_THREADS := 1

.PHONY: run test lint install browser linuxcnc bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	$(PY) -m planner
	touch $(STAMP)

install: $(STAMP)

run: $(STAMP)
	$(VENV)/bin/rangeplan serve

# Browser tests drive Debian's Chromium (never a browser download of Playwright's own).
browser:
	@test -x /usr/bin/chromium || { echo "installing Debian chromium for the browser tests"; \
	  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
	  chromium chromium-driver >/dev/null; }

# G-code tests run every program through LinuxCNC's own interpreter (rs274) and stream the
# leg lengths through halstreamer: Debian's linuxcnc-uspace
linuxcnc:
	@test -x /usr/bin/rs274 -a -x /usr/bin/halstreamer || { echo "installing Debian linuxcnc-uspace for the G-code tests"; \
	  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
	  linuxcnc-uspace >/dev/null; }

# ruff (style and errors), pyright (types), import-linter (the layers of planner/ and app/)
lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/pyright
	$(VENV)/bin/lint-imports

test: $(STAMP) browser linuxcnc lint
	$(PY) -m pytest -q

bench: $(STAMP)
	$(PY) benchmarks/bench_planner.py

clean:
	rm -rf $(VENV) build *.egg-info
