"""Property-based fuzzing of the whole API from its OpenAPI document (issue 15), the quick
profile of ``make test``: schemathesis with every check, 100 examples per operation and the
stateful phase through the OpenAPI links, against a real server with the token on
(:mod:`tests.fuzz.runner`). No server error, no check failure; the full run's figures are
in benchmarks/README.md (``benchmarks/fuzz_api.py``)."""

from __future__ import annotations

import pytest

pytest.importorskip("schemathesis")

from tests.fuzz.runner import run

#: operations with inputs to vary (the probes and the robot list have none or few)
VARIED = ["POST /v1/plan", "POST /v1/segment", "POST /v1/corridors", "GET /v1/corridors",
          "PUT /v1/corridors/{corridor_id}", "GET /v1/corridors/{corridor_id}",
          "DELETE /v1/corridors/{corridor_id}", "POST /v1/corridors/{corridor_id}/plan",
          "GET /v1/plans/{plan_id}", "GET /v1/robots/{name}", "POST /v1/import", "POST /v1/batches",
          "GET /v1/batches", "GET /v1/batches/{batch_id}", "GET /v1/batches/{batch_id}/results",
          "POST /v1/batches/{batch_id}/cancel", "DELETE /v1/batches/{batch_id}"]


@pytest.mark.slow
def test_schemathesis_all_checks_stateful_no_failures():
    report = run(max_examples=100)
    assert report.exit_code == 0, report.output
    assert report.failures == [] and report.errors == [], report.output
    assert report.server_errors == 0 and report.server_tracebacks == 0, report.server_error_lines
    assert report.server_exit == 0
    for op in VARIED:
        assert report.per_operation.get(op, 0) >= 100, (op, report.per_operation)
    assert report.stateful_cases > 0
