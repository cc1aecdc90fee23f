"""Shared test data and helpers (fixtures in conftest.py use these)."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "app" / "static" / "examples"
#: the paper's Table I corridor: the one copy the tests read
TABLE1_PATH = EXAMPLES / "table1.json"


def load_example(name: str) -> dict[str, Any]:
    """A request from ``app/static/examples/<name>.json`` (a fresh copy)."""
    return json.loads((EXAMPLES / f"{name}.json").read_text())


TABLE1: dict[str, Any] = load_example("table1")
PSI_TURN: dict[str, Any] = load_example("psi-turn")


def with_settings(request: dict[str, Any], **settings: Any) -> dict[str, Any]:
    """A copy of ``request`` with ``settings`` updated."""
    out = copy.deepcopy(request)
    out["settings"] = {**out.get("settings", {}), **settings}
    return out


def plan_json(request: Any, **kwargs: Any) -> dict[str, Any]:
    """``planner.plan`` with the result as JSON types (what a client reads)."""
    from planner import plan

    return plan(request, **kwargs).to_json_dict()


def robot_description(name: str) -> dict[str, Any]:
    """A built-in robot's description as a JSON dict (to modify in a test)."""
    from planner.schema import builtin_description

    return builtin_description(name).model_dump(mode="json")


#: the address an in-process API client uses: a loopback name, which the Host allow-list
#: (app.security) answers; TestClient's default host "testserver" is refused with 400
LOCAL_URL = "http://localhost"


def api_client(app: Any, **kwargs: Any):
    """A ``TestClient`` for ``app`` that talks to it as a local client does (Host localhost)."""
    from fastapi.testclient import TestClient

    return TestClient(app, base_url=LOCAL_URL, **kwargs)


#: Python run at the start of every process with it on PYTHONPATH (a ``sitecustomize``): the
#: slack work of a constrained plan with ``require_settled: false`` made ~free in the work
#: estimate, and so (its bound being what the estimate counts) unbounded: a work estimate far
#: below the time a request takes, as the tests of the compute limit need (a safety net for an
#: estimate that is wrong; since issue 20 the estimate bounds the slack work, which was the
#: runaway these tests used)
MISCALIBRATED_SLACK = """
from planner.schema import limits as _limits
_limits.WORK_COSTS.update(slack_step_a=1e-9, slack_step_d=0.0, slack_iteration_a=1e-12, slack_iteration_c=0.0)
import planner.orchestrator.work as _work
_work.SLACK_BUDGET_S = 1e-3
"""


def miscalibrate_slack(monkeypatch: Any, tmp_path: Path) -> dict[str, str]:
    """:data:`MISCALIBRATED_SLACK` in this process (monkeypatched) and the environment that
    gives it to the processes started from here (returned; also set in ``os.environ``)."""
    import os

    from planner.orchestrator import work
    from planner.schema import limits

    for key, value in (("slack_step_a", 1e-9), ("slack_step_d", 0.0), ("slack_iteration_a", 1e-12),
                       ("slack_iteration_c", 0.0)):
        monkeypatch.setitem(limits.WORK_COSTS, key, value)
    monkeypatch.setattr(work, "SLACK_BUDGET_S", 1e-3)
    site = tmp_path / "miscalibrated-site"
    site.mkdir(exist_ok=True)
    (site / "sitecustomize.py").write_text(MISCALIBRATED_SLACK)
    path = os.pathsep.join(p for p in (str(site), os.environ.get("PYTHONPATH", "")) if p)
    monkeypatch.setenv("PYTHONPATH", path)
    return {"PYTHONPATH": path}
