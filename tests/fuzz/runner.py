"""A schemathesis run against a real `rangeplan serve` (issue 15): every check
(``--checks all``), the examples, coverage, fuzzing and stateful phases (the OpenAPI links:
create a corridor -> get, replace, plan, delete it; a plan -> fetch it again; a page -> the
next page), with the token, against a server with two workers and a 3 s compute limit.

Used by ``tests/test_api_fuzz.py`` (the quick profile of ``make test``: 100 examples per
operation) and ``benchmarks/fuzz_api.py`` (the full run; figures in benchmarks/README.md).
"""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parents[2]
CONFIG = Path(__file__).resolve().parent / "schemathesis.toml"
TOKEN = "fuzz-token-0123456789abcdef"


@dataclass
class FuzzReport:
    exit_code: int  #: schemathesis's exit status (0: no failure)
    generated: int  #: test cases schemathesis generated
    failures: list  #: schemathesis's failure groups
    errors: list  #: errors of the run itself
    per_operation: dict[str, int] = field(default_factory=dict)  #: requests the server got per "METHOD /template"
    stateful_cases: int = 0  #: test cases of the stateful phase (chains of linked operations)
    server_errors: int = 0  #: 5xx answers the server logged (but /ready's 503 while starting)
    server_error_lines: list = field(default_factory=list)  #: their access-log lines
    server_tracebacks: int = 0  #: tracebacks in the server's log
    server_exit: int | None = None  #: the server's exit status after SIGTERM
    seconds: float = 0.0  #: the schemathesis run's wall time
    top_ups: int = 0  #: operations given a fuzzing pass of their own
    output: str = ""  #: the end of schemathesis's report


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _to_templates(received: Counter, operations: list[str]) -> dict[str, int]:
    """Requests per concrete "METHOD /path" counted under their operation
    ("DELETE /v1/corridors/3f2a..." under "DELETE /v1/corridors/{corridor_id}"); others
    (methods the document does not have, unknown paths) under their own key."""
    rx = [(op, re.compile("^" + re.sub(r"\\\{[^}]+\\\}", "[^/]+", re.escape(op.split(" ", 1)[1])) + "$"))
          for op in operations]
    out: Counter = Counter()
    for key, n in received.items():
        method, _, path = key.partition(" ")
        matches = [op for op, r in rx if op.startswith(method + " ") and r.match(path)]
        # a fixed path (/v1/corridors) before a template that also matches it
        out[min(matches, key=lambda op: op.count("{")) if matches else key] += n
    return dict(out)


def _access_lines(log_text: str) -> list[dict]:
    """The server's JSON access lines (app.observability: method, path, status, ...)."""
    out = []
    for line in log_text.splitlines():
        if line.startswith("{") and '"rangeplan.access"' in line:
            try:
                out.append(json.loads(line))
            except ValueError:
                continue
    return out


def _received(log_text: str) -> Counter:
    """Requests per "METHOD /path" in the server's access lines."""
    return Counter(f"{a['method']} {a['path']}" for a in _access_lines(log_text))


def _schemathesis(url: str, cwd: Path, report_dir: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "schemathesis.cli", "--config-file", str(CONFIG), "run", f"{url}/openapi.json",
         "--checks", "all", "-H", f"Authorization: Bearer {TOKEN}", "--no-color", "--report", "json,ndjson",
         "--report-dir", str(report_dir), *args],
        cwd=cwd, capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})


def _start_server(tmpdir: Path, timeout_s: float, workers: int, token: str | None = TOKEN):
    """A `rangeplan serve` (no editor) on a free loopback port, once /ready: (process, log, url)."""
    port = _free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("RANGEPLAN_")}
    env.update({"RANGEPLAN_DATA_DIR": str(tmpdir / "data"), "RANGEPLAN_WORKERS": str(workers),
                "RANGEPLAN_PLAN_TIMEOUT_S": str(timeout_s), "RANGEPLAN_ACCESS_LOG": "1", "PYTHONPATH": str(ROOT),
                # jobs (202) under the same limit: with the default 600 s two fuzzed long jobs held both
                # workers while a synchronous plan waited past the client's 10 s read timeout (seen
                # once the admission margin made estimates of 2-3 s jobs under a 3 s limit)
                "RANGEPLAN_JOB_TIMEOUT_S": str(timeout_s)})
    if token:
        env["RANGEPLAN_API_TOKEN"] = token
    log = open(tmpdir / "server.log", "w+")
    server = subprocess.Popen([sys.executable, "-m", "app.cli", "serve", "--port", str(port), "--no-editor"],
                              env=env, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 180
    while True:
        if server.poll() is not None or time.monotonic() > deadline:
            server.kill()
            log.seek(0)
            raise RuntimeError(f"the server did not become ready: {log.read()[-2000:]}")
        try:
            if httpx.get(f"{url}/ready", timeout=2).status_code == 200:
                return server, log, url
        except httpx.HTTPError:
            pass
        time.sleep(0.2)


def run(max_examples: int = 100, seed: int = 1, timeout_s: float = 3.0, workers: int = 2) -> FuzzReport:
    """Start a server, run schemathesis against it, stop the server; see :class:`FuzzReport`."""
    with tempfile.TemporaryDirectory(prefix="rangeplan-fuzz-") as tmp:
        tmpdir = Path(tmp)
        report_dir = tmpdir / "report"
        server, log, url = _start_server(tmpdir, timeout_s, workers)
        try:
            doc = httpx.get(f"{url}/openapi.json", timeout=10).json()
            operations = [f"{m.upper()} {path}" for path, ops in doc["paths"].items() for m in ops]
            t0 = time.monotonic()
            st = _schemathesis(url, tmpdir, report_dir, "--max-examples", str(max_examples), "--seed", str(seed))
            # an operation whose path parameter schemathesis fills from the resources it created
            # (the ids of saved corridors) runs out of distinct inputs early: top it up with
            # generated ones, in a fuzzing pass of its own
            top_ups = []
            log.flush()
            log.seek(0)
            got = _to_templates(_received(log.read()), operations)
            for op in operations:
                method, path = op.split(" ", 1)
                spec = doc["paths"][path][method.lower()]
                has_inputs = bool(spec.get("parameters")) or "requestBody" in spec
                if has_inputs and got.get(op, 0) < max_examples:
                    top_ups.append(_schemathesis(url, tmpdir, tmpdir / f"top-up-{len(top_ups)}", "--max-examples",
                                                 str(max_examples), "--seed", str(seed), "--phases", "fuzzing",
                                                 "--include-method", method, "--include-path", path))
            seconds = time.monotonic() - t0
        finally:
            server.send_signal(signal.SIGTERM)
            try:
                server_exit = server.wait(30)
            except subprocess.TimeoutExpired:
                server.kill()
                server_exit = server.wait(5)
        summary = json.loads(next(report_dir.glob("*.json")).read_text())
        failures, run_errors, generated = list(summary["failures"]), list(summary["errors"]), 0
        for i in range(len(top_ups)):
            more = json.loads(next((tmpdir / f"top-up-{i}").glob("*.json")).read_text())
            failures += more["failures"]
            run_errors += more["errors"]
            generated += more["test_cases"]["generated"]
        stateful = 0
        for line in next(report_dir.glob("*.ndjson")).read_text().splitlines():
            done = json.loads(line).get("ScenarioFinished")
            if done and done.get("phase") == "stateful":
                stateful += len((done.get("recorder") or {}).get("cases") or {})
        log.seek(0)
        text = log.read()
        log.close()
        received = _received(text)
        # 5xx answers, but not /ready's 503 while the workers start (the probe doing its job)
        errors = [json.dumps(a) for a in _access_lines(text)
                  if int(a["status"]) >= 500 and not (a["method"] == "GET" and a["path"] == "/ready")]
        return FuzzReport(exit_code=max([st.returncode] + [t.returncode for t in top_ups]),
                          generated=summary["test_cases"]["generated"] + generated, failures=failures,
                          errors=run_errors, top_ups=len(top_ups),
                          per_operation=_to_templates(received, operations), stateful_cases=stateful,
                          server_errors=len(errors), server_error_lines=errors[:20],
                          server_tracebacks=text.count("Traceback (most recent call last)"), server_exit=server_exit,
                          seconds=seconds, output=st.stdout[-6000:] + st.stderr[-2000:])
