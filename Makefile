# rangeplan: `make run` and `make test` do all setup on a fresh clone.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp
RUNTIME := $(VENV)/.runtime-stamp

# Small dense matrices: single-threaded BLAS is much faster on these machines.
export OPENBLAS_NUM_THREADS := 1
export OMP_NUM_THREADS := 1
export MKL_NUM_THREADS := 1
# mkdocs-material's banner about MkDocs 2.0 on every build
export NO_MKDOCS_2_WARNING := 1

.PHONY: run test lint docs install kernels browser linuxcnc bench clean lock container-test smoke dist

# the runtime dependencies from the lock first (the versions the container image runs), then
# rangeplan (all `make run` needs), then its test tools around them
$(RUNTIME): pyproject.toml container/requirements.lock
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet --no-compile --require-hashes -r container/requirements.lock
	$(PY) -m pip install --quiet --no-compile --no-deps -e .
	touch $(RUNTIME)

# byte-compiled once here: with PYTHONDONTWRITEBYTECODE set (as on CI) and the runtime installed
# with --no-compile (the quick `make run`), every process the tests start would compile numpy,
# scipy, numba, pydantic and fastapi from source again (~3x their import time)
$(STAMP): $(RUNTIME)
	$(PY) -m pip install --quiet -e '.[test]'
	-$(PY) -m compileall -q -j 0 $(VENV)/lib planner app >/dev/null
	touch $(STAMP)

# compile the planner's kernels in the foreground (minutes once after installing, with progress;
# ~2 s when they are cached)
kernels: $(RUNTIME)
	$(PY) -m planner

install: $(STAMP) kernels

# the service starts at once: while the kernels are not compiled it compiles them in the
# background and plans on the numpy reference meanwhile (docs/install.md, "What the first run costs")
run: $(RUNTIME)
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

# ruff (style and errors), pyright (types), import-linter (the layers of planner/ and app/), and
# the manual built in strict mode (a broken link, anchor or API reference fails; never with
# --quiet, which hides the warnings --strict counts: a broken link then passes)
lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/pyright
	$(VENV)/bin/lint-imports
	$(VENV)/bin/mkdocs build --strict

# the manual (docs/, mkdocs.yml) into site/: MkDocs with the Material theme, offline (no fonts or
# scripts from the internet); the API reference from the docstrings (mkdocstrings), the HTTP API
# page from the service's OpenAPI document and the command reference from the CLI's parser
# (docs/hooks/generated.py). Open site/index.html.
docs: $(STAMP)
	$(VENV)/bin/mkdocs build --strict

# the lint (as `make lint`, the manual's strict build included) beside the tests in 2 processes
# (pytest-xdist; tests/conftest.py orders them, a group runs in one process), then alone the tests
# that bound a wall time or a latency (marker `serial`); fails if any part fails
test: $(STAMP) kernels browser linuxcnc
	@log=$$(mktemp); { $(VENV)/bin/ruff check . && $(VENV)/bin/pyright && $(VENV)/bin/lint-imports \
	  && $(VENV)/bin/mkdocs build --strict; } >$$log 2>&1 & \
	lint=$$!; \
	$(PY) -m pytest -q -n 2 --dist loadgroup --no-loadscope-reorder -m "not serial" --durations=40; tests=$$?; \
	wait $$lint; linted=$$?; cat $$log; rm -f $$log; \
	$(PY) -m pytest -q -m serial --durations=10; serial=$$?; \
	echo "lint: exit $$linted; tests in parallel: exit $$tests; serial tests: exit $$serial"; \
	[ $$linted = 0 ] && [ $$tests = 0 ] && [ $$serial = 0 ]
	@# what users install: the wheel in a fresh venv, then the image (tests/test_smoke.py, test_container.py)
	$(MAKE) --no-print-directory smoke
	$(MAKE) --no-print-directory container-test

# what users install: `python -m build` makes the sdist and, from it, the wheel (dist/)
dist: $(STAMP)
	rm -rf dist
	$(PY) -m build --no-isolation --outdir dist . >/dev/null

# the built wheel installed non-editable into a fresh venv (the locked dependencies, as the image
# has them), and the smoke suite run against that install, not the tree (tests/test_smoke.py)
WHEEL_VENV := .venv-wheel
smoke: dist kernels
	rm -rf $(WHEEL_VENV)
	$(PYTHON) -m venv $(WHEEL_VENV)
	$(WHEEL_VENV)/bin/python -m pip install --quiet --require-hashes -r container/requirements.lock
	$(WHEEL_VENV)/bin/python -m pip install --quiet --no-deps dist/rangeplan-*.whl
	RANGEPLAN_SMOKE_VENV=$(WHEEL_VENV) $(PY) -m pytest -q -p no:cacheprovider -m smoke tests/test_smoke.py

bench: $(STAMP) kernels
	$(PY) benchmarks/bench_planner.py

# re-pin the runtime dependencies of pyproject.toml (with hashes) for the image and `make install`
lock: $(STAMP)
	$(PY) -m pip install --quiet "pip-tools>=7.4"
	$(VENV)/bin/pip-compile --quiet --generate-hashes --strip-extras --allow-unsafe --no-emit-index-url \
	  --no-emit-find-links --output-file container/requirements.lock pyproject.toml

# Part of `make test` (root; podman, or CONTAINER_ENGINE=docker with a running engine): build
# the image and run it as a deployment would (tests/test_container.py) and the smoke suite
# against it (tests/test_smoke.py). Without access to a registry the base image is a stand-in
# built from Debian packages (container/stand-in-base.sh, debootstrap); the output says so.
# podman by default: a docker client may be installed where no engine runs.
CONTAINER_ENGINE ?= podman
BASE_IMAGE ?= python:3.11-slim
IMAGE ?= localhost/rangeplan:test
container-test: $(STAMP)
	@if [ "$(CONTAINER_ENGINE)" = podman ]; then for tool in podman runc debootstrap; do \
	  command -v $$tool >/dev/null 2>&1 || { echo "installing podman and debootstrap from Debian"; \
	  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
	  podman runc buildah fuse-overlayfs uidmap debootstrap >/dev/null; break; }; done; fi
	CONTAINER_ENGINE=$(CONTAINER_ENGINE) BASE_IMAGE=$(BASE_IMAGE) IMAGE=$(IMAGE) container/build.sh
	RANGEPLAN_CONTAINER_IMAGE=$(IMAGE) CONTAINER_ENGINE=$(CONTAINER_ENGINE) $(PY) -m pytest -q -p no:cacheprovider \
	  -m "container or smoke" tests/test_container.py tests/test_smoke.py

clean:
	rm -rf $(VENV) build *.egg-info site
