"""Fixtures shared by the test modules; markers (``slow``, ``browser``) are registered in
pyproject.toml."""

from __future__ import annotations

import copy
import os

import pytest

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from tests.support import PSI_TURN, TABLE1  # noqa: E402  (BLAS threads are fixed before numpy loads)


@pytest.fixture
def table1() -> dict:
    """The paper's Table I corridor request (a fresh copy)."""
    return copy.deepcopy(TABLE1)


@pytest.fixture
def psi_turn() -> dict:
    """The turning-platform example: psi ranges per segment (a fresh copy)."""
    return copy.deepcopy(PSI_TURN)


#: modules whose tests one pytest-xdist process runs, in order (``make test``: ``--dist loadgroup``;
#: xdist 3.8's own ``xdist_group`` marker groups nothing under pytest 9.2: it renames ``item._nodeid``,
#: which pytest 9.2 no longer reads; pytest-xdist issue 1386)
ONE_PROCESS = {
    "tests/test_editor_browser.py": "one chromium at a time: its software WebGL takes a core",
    "tests/test_batch_cluster.py": "one command-line Dask cluster for the module's tests",
}


def pytest_xdist_make_scheduler(config: pytest.Config, log):
    """``--dist loadgroup``: each test on its own, but the modules of :data:`ONE_PROCESS`
    whole, in one process."""
    if config.getvalue("dist") != "loadgroup":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class _Scheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            module = nodeid.split("::", 1)[0]
            return module if module in ONE_PROCESS else nodeid

    return _Scheduling(config, log)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """In pytest-xdist's worker processes (``make test``: ``-n 2 --dist loadgroup
    --no-loadscope-reorder``, which hands the tests out in this order): the browser tests
    first (one process, ~7 min), then the other modules with a long test (marked ``slow``),
    then the rest, each module's tests together and in their order, so that no long test
    starts last while the other process has nothing left to do. A run without xdist keeps
    pytest's order."""
    if not hasattr(config, "workerinput"):
        return
    rank: dict = {}
    for item in items:
        r = 0 if item.get_closest_marker("browser") else 1 if item.get_closest_marker("slow") else 2
        rank[item.module] = min(rank.get(item.module, 2), r)
    items.sort(key=lambda item: rank[item.module])  # stable: the order within each part is kept
