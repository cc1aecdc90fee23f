# rangeplan: the HTTP planning API (port 8000) and the browser corridor editor (port 8080).
#   docker build -t rangeplan .
#   docker run --rm -p 8000:8000 -p 8080:8080 -v rangeplan-data:/data rangeplan
# The install steps below are the Makefile's ($(STAMP) recipe, what `make run` runs) with
# PYTHON=python, so the image runs what CI tests; tests/test_dockerfile.py keeps them identical.
# The last step compiles the planner's numba kernels into planner/__pycache__ (cached on disk).
FROM python:3.11-slim

# same environment as the Makefile exports (single-threaded BLAS for small dense matrices)
ENV OPENBLAS_NUM_THREADS=1 \
    OMP_NUM_THREADS=1 \
    MKL_NUM_THREADS=1 \
    PYTHONUNBUFFERED=1 \
    PYTHONDONTWRITEBYTECODE=1 \
    RANGEPLAN_DATA_DIR=/data \
    RANGEPLAN_PORT=8000 \
    RANGEPLAN_EDITOR_PORT=8080

RUN useradd --create-home --uid 10001 --shell /usr/sbin/nologin rangeplan \
    && mkdir -p /data /app \
    && chown rangeplan:rangeplan /data /app

WORKDIR /app
COPY --chown=rangeplan:rangeplan . /app
USER rangeplan

RUN python -m venv .venv \
    && .venv/bin/python -m pip install --quiet --upgrade pip \
    && .venv/bin/python -m pip install --quiet -e '.[test]' \
    && .venv/bin/python -m planner

ENV PATH=/app/.venv/bin:$PATH
VOLUME ["/data"]
EXPOSE 8000 8080

HEALTHCHECK --interval=30s --timeout=5s --start-period=20s --retries=3 \
    CMD ["python", "-c", "import os, urllib.request; urllib.request.urlopen('http://127.0.0.1:%s/health' % os.environ.get('RANGEPLAN_PORT', '8000'), timeout=4)"]

# exec form: the server is PID 1 and gets SIGTERM from `docker stop` (graceful, exit 0)
CMD ["rangeplan", "serve", "--host", "0.0.0.0"]
