"""Fixtures shared by the test modules; markers (``slow``, ``browser``) are registered in
pyproject.toml."""

from __future__ import annotations

import copy
import os

import pytest

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
# no test starts the CLI's resident planner (app/resident.py) unless it sets this itself:
# a resident outlives the command that starts it
os.environ["RANGEPLAN_RESIDENT_S"] = "0"

from tests.support import PSI_TURN, TABLE1  # noqa: E402  (BLAS threads are fixed before numpy loads)


@pytest.fixture
def table1() -> dict:
    """The paper's Table I corridor request (a fresh copy)."""
    return copy.deepcopy(TABLE1)


@pytest.fixture
def psi_turn() -> dict:
    """The turning-platform example: psi ranges per segment (a fresh copy)."""
    return copy.deepcopy(PSI_TURN)
