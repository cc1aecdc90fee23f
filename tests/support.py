"""Shared test data and helpers (fixtures in conftest.py use these)."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "static" / "examples"
#: the paper's Table I corridor: the one copy the tests read
TABLE1_PATH = EXAMPLES / "table1.json"


def load_example(name: str) -> dict[str, Any]:
    """A request from ``static/examples/<name>.json`` (a fresh copy)."""
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
