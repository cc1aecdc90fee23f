"""Property-based fuzzing of the whole API from its OpenAPI spec (schemathesis): for
generated requests, no 5xx, and every response conforms to the documented status codes,
content types and schemas (errors included). Bounded: a few examples per operation."""

from __future__ import annotations

import tempfile

import pytest

schemathesis = pytest.importorskip("schemathesis")
from hypothesis import HealthCheck, settings  # noqa: E402
from schemathesis.checks import (  # noqa: E402
    content_type_conformance,
    not_a_server_error,
    response_schema_conformance,
    status_code_conformance,
)

from app.api import create_app  # noqa: E402
from app.storage import Store  # noqa: E402

_tmp = tempfile.TemporaryDirectory(prefix="rangeplan-fuzz-")
# short compute limit: a generated request that would plan for minutes answers 422 timeout
app = create_app(Store(_tmp.name), workers=2, timeout_s=3.0)
schema = schemathesis.openapi.from_asgi("/openapi.json", app)


@pytest.fixture(scope="module", autouse=True)
def _cleanup():
    yield
    app.state.close_pool()
    _tmp.cleanup()


@schema.parametrize()
@settings(max_examples=12, deadline=None, derandomize=True, database=None,
          suppress_health_check=list(HealthCheck))
def test_api_conforms_and_never_5xx(case):
    response = case.call()
    case.validate_response(response, checks=[not_a_server_error, status_code_conformance,
                                             content_type_conformance, response_schema_conformance])
