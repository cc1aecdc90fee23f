# rangeplan: the HTTP planning API (port 8000) and the browser corridor editor (port 8080).
#   docker build -t rangeplan .            (podman: podman build --format docker -t rangeplan .)
#   docker run --rm -p 8000:8000 -p 8080:8080 -v rangeplan-data:/data \
#       -e RANGEPLAN_API_TOKEN=... -e RANGEPLAN_ALLOWED_HOSTS=cad-host.example rangeplan
# Also runs `--read-only --tmpfs /tmp --user <any uid>:0` (Kubernetes runAsUser, OpenShift).
# An air-gapped site builds on its own copy of the base: --build-arg BASE_IMAGE=registry.local/python:3.11-slim
# (`make container-test` builds a stand-in from Debian packages when no registry is reachable).
#
# Stages: deps (the locked runtime dependencies, rebuilt only when container/requirements.lock
# changes), app (the rangeplan wheel: the planner, the service, the landing page and its examples),
# runtime (deps + wheel + kernels compiled for any x86-64).
# Tests run in CI, not here: the image holds no test tools. tests/test_dockerfile.py checks
# this file and that the lock matches pyproject.toml (`make lock` rewrites it).
ARG BASE_IMAGE=python:3.11-slim
# planner/_version.py's; the build fails if the wheel says otherwise (tests/test_dockerfile.py)
ARG RANGEPLAN_VERSION=0.2.0

# ---------------------------------------------------------------------------------------
FROM ${BASE_IMAGE} AS deps
ENV PIP_NO_CACHE_DIR=1 PIP_DISABLE_PIP_VERSION_CHECK=1 PYTHONDONTWRITEBYTECODE=1
COPY container/requirements.lock /tmp/requirements.lock
# a venv without pip (the base's pip installs into it); hashes checked; dropped, never
# imported (~130 MB): every package's test suite, the C, C++ and Cython sources, headers
# and type stubs shipped in the wheels, viser's client sources (the built client stays),
# dask's collections (dask.dataframe needs pandas, which is not installed; batches use only
# distributed's executor) and pygments (rich's syntax highlighting; the batch progress bar
# does not use it) and numba's CUDA target (3 MB; imported only for target="cuda", which the
# planner never uses); the symbol tables of the packages' compiled
# modules stripped (57 MB; binutils only in this stage, skipped if the Debian mirror cannot be
# reached; not the vendored *.libs, which patchelf has rewritten), then every compiled
# dependency imported once so that a broken library fails the build, not the service
RUN python -m venv --without-pip /opt/venv \
    && python -m pip --python /opt/venv/bin/python install --quiet --no-deps --require-hashes \
       -r /tmp/requirements.lock \
    && cd /opt/venv/lib/python3.11/site-packages \
    && find . -depth -type d \( -name tests -o -name test \) -exec rm -rf {} + \
    && find . -type f \( -name "*.c" -o -name "*.cpp" -o -name "*.h" -o -name "*.hpp" -o -name "*.pyx" \
       -o -name "*.pxd" -o -name "*.pyi" \) -delete \
    && rm -rf viser/client/src dask/dataframe dask/array dask/bag pygments numba/cuda && cd / \
    && rm /tmp/requirements.lock \
    && if command -v strip >/dev/null || { apt-get update -qq && DEBIAN_FRONTEND=noninteractive \
          apt-get install -y -qq --no-install-recommends binutils >/dev/null; }; then \
         find /opt/venv -type f \( -name "*.so" -o -name "*.so.*" \) -not -path "*.libs/*" \
           -exec strip --strip-unneeded {} + ; \
       else echo "binutils not available: libraries left unstripped (image ~60 MB larger)"; fi \
    && /opt/venv/bin/python -c "import numpy, scipy.linalg, scipy.sparse.csgraph, numba, llvmlite.binding, \
shapely, daqp, PIL.Image, zstandard, orjson, msgspec, pydantic_core, websockets, viser, uvicorn, fastapi, \
ezdxf, svgelements, python_multipart, msgpack, psutil, tornado, yaml, dask, distributed, rich.progress"

# ---------------------------------------------------------------------------------------
FROM ${BASE_IMAGE} AS app
ENV PIP_NO_CACHE_DIR=1 PIP_DISABLE_PIP_VERSION_CHECK=1
COPY pyproject.toml README.md /src/
COPY planner /src/planner
COPY app /src/app
RUN python -m pip wheel --quiet --no-deps --wheel-dir /wheels /src

# ---------------------------------------------------------------------------------------
FROM ${BASE_IMAGE} AS runtime
ARG RANGEPLAN_VERSION
LABEL org.opencontainers.image.title="rangeplan" \
      org.opencontainers.image.version="${RANGEPLAN_VERSION}" \
      org.opencontainers.image.description="Offline trajectory planner for planar parallel robots: HTTP API and editor"
ENV OPENBLAS_NUM_THREADS=1 \
    OMP_NUM_THREADS=1 \
    MKL_NUM_THREADS=1 \
    PYTHONUNBUFFERED=1 \
    PYTHONDONTWRITEBYTECODE=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    HOME=/tmp \
    NUMBA_CPU_NAME=generic \
    NUMBA_CACHE_DIR=/tmp/rangeplan-numba \
    RANGEPLAN_KERNEL_SEED=/opt/rangeplan/kernels \
    RANGEPLAN_DATA_DIR=/data \
    RANGEPLAN_PORT=8000 \
    RANGEPLAN_EDITOR_PORT=8080

# the service user owns only /data; group 0 may write it too (any uid run with gid 0)
RUN useradd --uid 10001 --gid 0 --no-create-home --home-dir /tmp --shell /usr/sbin/nologin rangeplan \
    && mkdir -p /data && chown 10001:0 /data && chmod 2775 /data

# the dependencies (one layer, unchanged by source edits), then the application (small),
# installed by the base image's pip (the venv has none)
COPY --from=deps /opt/venv /opt/venv
COPY --from=app /wheels /tmp/wheels
RUN python -m pip --python /opt/venv/bin/python install --quiet --no-deps --no-index /tmp/wheels/*.whl \
    && rm -rf /tmp/wheels \
    && test "$(/opt/venv/bin/python -c 'import planner; print(planner.__version__)')" = "${RANGEPLAN_VERSION}"

# compile the planner's kernels for a generic x86-64 CPU (NUMBA_CPU_NAME=generic: the cache
# is not tied to the build machine's CPU) into a read-only seed; `rangeplan serve` copies it
# to NUMBA_CACHE_DIR on the tmpfs at start (app/kernel_cache.py). The build's cache mount keeps
# the kernels between builds (keyed by the kernel sources' content, planner/_jit.py): a rebuild
# whose kernels did not change loads them in seconds instead of compiling them for minutes.
RUN --mount=type=cache,target=/var/cache/rangeplan-kernels,sharing=locked \
    NUMBA_CACHE_DIR=/var/cache/rangeplan-kernels /opt/venv/bin/python -m planner \
    && mkdir -p /opt/rangeplan/kernels \
    && cp -a "$(NUMBA_CACHE_DIR=/var/cache/rangeplan-kernels /opt/venv/bin/python -c \
       'from planner._jit import kernel_cache_dir; print(kernel_cache_dir())')" /opt/rangeplan/kernels/ \
    && chown -R 0:0 /opt/rangeplan && chmod -R a+rX,go-w /opt/rangeplan
ENV PATH=/opt/venv/bin:$PATH

USER 10001:0
VOLUME ["/data"]
EXPOSE 8000 8080

# ready = the workers have loaded the kernels and can plan (/health would say ok before)
HEALTHCHECK --interval=30s --timeout=5s --start-period=30s --retries=3 \
    CMD ["python", "-c", "import os, urllib.request; urllib.request.urlopen('http://127.0.0.1:%s/ready' % os.environ.get('RANGEPLAN_PORT', '8000'), timeout=4)"]

# exec form: the server is PID 1 and gets SIGTERM from `docker stop` (graceful, exit 0).
# Bound to all interfaces, it refuses to start without RANGEPLAN_API_TOKEN(_FILE).
CMD ["rangeplan", "serve", "--host", "0.0.0.0"]
