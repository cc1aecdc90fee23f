"""Batches on a local process pool: the engine function, the dispatcher's retries, the
``rangeplan batch`` CLI (results equal ``rangeplan plan``, bad items reported with their
code, progress, summary.csv, resume, Ctrl-C) and ``/v1/batches`` (202, progress, JSON Lines
in item order, CSV summary, cancel, restart, a separate low-priority pool)."""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import threading
import time
from concurrent.futures import Future
from pathlib import Path

import pytest

from app.api import create_app
from app.batch.config import FORMAT_NAMES
from app.batch.engine import FORMATS, plan_item
from app.batch.executors import Engine
from app.batch.runner import Item, Runner
from app.executors import InProcessExecutor
from app.storage import Store
from app.workers import WORKER_NICE, WorkerCrashed
from planner import plan
from tests.batch_support import (
    BAD_RANGE,
    CLI,
    UNREACHABLE,
    assert_same_plan,
    env,
    planning_children,
    read_summary,
    single_plan,
    variant,
    write_jsonl,
)
from tests.support import TABLE1, api_client

# ---------------------------------------------------------------------------------------
# the engine function and the dispatcher

def test_formats_named_in_config_are_the_engines():
    assert tuple(FORMATS) == FORMAT_NAMES


def test_plan_item_returns_the_plans_bytes_and_where_it_ran():
    out = plan_item(json.dumps(TABLE1), "json")
    assert out["status"] == "ok" and out["engine"] == "inline" and out["pid"] == os.getpid()
    ref = plan(TABLE1).to_json_dict()
    got = json.loads(out["payload"])
    assert_same_plan(got, ref, tol=0.0)
    assert out["summary"]["energy"] == ref["metrics"]["energy"]
    assert out["summary"]["duration_s"] == ref["metrics"]["duration_s"]
    csv_out = plan_item(TABLE1, "csv")
    assert csv_out["payload"].decode().splitlines()[0].startswith("time_s,x_m,y_m,psi_rad")
    assert plan_item(TABLE1, "none")["payload"] is None


@pytest.mark.parametrize("request_, code, field", [
    (json.dumps(BAD_RANGE), "invalid_input", "segments[0].lower"),
    (json.dumps(UNREACHABLE), "unreachable", "segments[1]"),
    ("{not json", "invalid_input", None),
    ('{"segments": [], "bogus": 1}', "invalid_input", None),
])
def test_plan_item_reports_the_requests_fault_with_its_code(request_, code, field):
    out = plan_item(request_)
    assert out["status"] == "error" and out["payload"] is None
    assert out["error"]["code"] == code
    if field is not None:
        assert out["error"]["field"] == field
    assert out["error"]["message"]


@pytest.mark.serial  # two plan times compared
def test_plan_item_stops_at_the_compute_limit(monkeypatch):
    # a constrained plan of 12 x 1000 samples (~0.5 s or more), limited to a quarter of its
    # time: the planning process it runs in (a child of this one) is killed at the limit.
    # The work estimate is a lower estimate (what it accepts may still run into the limit):
    # here it accepts everything, so that the plan starts and the limit has to stop it
    import app.jobs as jobs
    from planner import WorkEstimate

    # (the estimate of every job, made in this process before the job is sent)
    monkeypatch.setattr(jobs, "estimate", lambda job: WorkEstimate(0.0, 1, 1, "segments", "none"))
    req = variant(0, "constrained")
    req["settings"]["samples_per_segment"] = 1000
    assert plan_item(variant(0, "constrained"), timeout_s=120)["status"] == "ok"  # the planning process started
    t0 = time.perf_counter()
    full = plan_item(req, timeout_s=120)
    full_s = time.perf_counter() - t0
    assert full["status"] == "ok"
    before = planning_children()
    t0 = time.perf_counter()
    out = plan_item(req, timeout_s=0.25 * full_s)
    assert out["status"] == "error" and out["error"]["code"] == "timeout"
    assert time.perf_counter() - t0 < 0.75 * full_s, (time.perf_counter() - t0, full_s)
    after = planning_children()
    assert after and not set(before) & set(after)  # the process was killed and replaced
    assert all(not os.path.exists(f"/proc/{p}") or "zombie" in open(f"/proc/{p}/status").read().lower()
               for p in before) or sys.platform != "linux"
    ok = plan_item(req, timeout_s=120)  # the next item plans in the new process
    assert ok["status"] == "ok" and ok["summary"] == full["summary"] | {"compute_ms": ok["summary"]["compute_ms"]}


@pytest.mark.slow
def test_a_sleep_job_is_cut_at_its_limit_and_the_local_worker_plans_the_next():
    """On a local pool (the service's PlanPool): a chunk's job runs in a child of the pool's
    worker, which is killed at the job's limit; the worker itself (same pid) lives on and runs
    the chunk's next job, and then a batch chunk's items."""
    from app.batch.engine import BatchChunkJob, chunk_outcomes
    from app.batch.executors import LocalEngine
    from tests.batch_support import SleepChunk

    engine = LocalEngine(1)
    try:
        t0 = time.perf_counter()
        probe = engine.executor.submit(SleepChunk((0.05, 120.0, 0.05), 1.0), 0.0).result(300)
        took = time.perf_counter() - t0
        pid, (first, cut, after) = probe.summary["pid"], probe.summary["runs"]
        assert pid in engine.pids() and pid != os.getpid()
        assert first["ok"] and first["children"] and pid not in first["children"]  # its planning process
        assert not cut["ok"] and cut["code"] == "timeout" and "1 s" in cut["message"], cut
        assert 1.0 <= cut["took_s"] < 20.0 and took < 60.0, (cut, took)
        assert after["ok"] and not set(after["children"]) & set(first["children"])  # a new planning process
        job = BatchChunkJob((json.dumps(TABLE1),), "json", 60.0, None, None, "local")
        res, = chunk_outcomes(engine.executor.submit(job, 0.0).result(300))
        assert res["status"] == "ok" and res["pid"] == pid and res["engine"] == "local"
        assert json.loads(bytes(res["payload"]))["metrics"]["duration_s"] == plan(TABLE1).metrics.duration_s
    finally:
        engine.close(cancel=True)


class _HookExecutor(InProcessExecutor):
    """Runs each submitted chunk in this process at submit; ``hook(job)`` decides its outcome
    (raising :class:`WorkerCrashed` as a pool whose worker died under the chunk does)."""

    def __init__(self, hook):
        super().__init__(0.0)
        self.hook = hook
        self.crashes = 0

    def submit(self, job, timeout_s=None):
        f: Future = Future()
        try:
            f.set_result(self.hook(job))
        except WorkerCrashed as exc:
            self.crashes += 1
            f.set_exception(exc)
        return f


class _InlineEngine(Engine):
    name = "local"

    def __init__(self, hook):
        self.hooked = _HookExecutor(hook)
        super().__init__(self.hooked)

    @property
    def slots(self):
        return 2


class _PoisonEngine(_InlineEngine):
    """Runs chunks inline; a chunk holding the poison request 'crashes its worker' (its future
    raises WorkerCrashed like a local pool's whose worker died under it)."""

    name = "poison"

    def __init__(self):
        self.submitted: list[list] = []

        def hook(job):
            self.submitted.append(list(job.requests))
            if any(r == "POISON" for r in job.requests):
                raise WorkerCrashed("a worker died")
            return job.run()
        super().__init__(hook)


def test_runner_finds_the_item_that_kills_its_worker_and_charges_no_other():
    engine = _PoisonEngine()
    reqs = [json.dumps(variant(i)) for i in range(6)]
    reqs.insert(2, "POISON")
    outcomes: dict[int, dict] = {}
    Runner(engine, lambda it, oc: outcomes.__setitem__(it.index, oc), max_attempts=3).run(
        [Item(i, str(i), request=r) for i, r in enumerate(reqs)])
    assert sorted(outcomes) == list(range(7))
    assert outcomes[2]["status"] == "failed" and outcomes[2]["error"]["code"] == "worker_died"
    assert outcomes[2]["attempts"] == 3
    for i, oc in outcomes.items():
        if i != 2:
            assert oc["status"] == "ok", oc
            assert oc["attempts"] <= 2  # charged at most the one shared crash
    assert engine.hooked.crashes == 3
    # after the first crash the poison ran alone each time
    assert [r for r in engine.submitted if "POISON" in r][1:] == [["POISON"], ["POISON"]]


# ---------------------------------------------------------------------------------------
# results written by the workers (a staging directory in OUTDIR, renamed into place)

def _files(outdir: Path) -> list[str]:
    """Everything in ``outdir``, hidden entries included (a staging directory left behind)."""
    return sorted(p.name for p in outdir.iterdir())


def test_plan_chunk_writes_where_it_sees_the_staging_directory_and_sends_back_otherwise(tmp_path):
    from app.batch.engine import plan_chunk, unpack_chunk

    stage = tmp_path / ".rangeplan-staging-test"
    stage.mkdir()
    reqs = [json.dumps(variant(0)), json.dumps(BAD_RANGE), json.dumps(variant(1))]
    written = unpack_chunk(plan_chunk(reqs, "json", None, str(stage)))
    assert [o["status"] for o in written] == ["ok", "error", "ok"]
    assert all(o["payload"] is None for o in written) and written[1].get("staged") is None
    files = sorted(p.name for p in stage.iterdir())
    assert sorted(o["staged"] for o in written if o["status"] == "ok") == files
    for o, i in ((written[0], 0), (written[2], 1)):
        data = (stage / o["staged"]).read_bytes()
        assert o["bytes"] == len(data)
        assert_same_plan(json.loads(data), plan(variant(i)).to_json_dict(), tol=0.0)
    # a worker that does not see the directory (another host, no shared filesystem): the results travel
    packed = plan_chunk(reqs, "json", None, str(tmp_path / ".rangeplan-staging-elsewhere"))
    sent = unpack_chunk(packed)
    assert all("staged" not in o for o in sent)
    assert len(packed["blob"]) == sum(len(o["payload"]) for o in sent if o["payload"] is not None)
    for o, w in zip(sent, written):
        if o["status"] == "ok":
            assert json.loads(bytes(o["payload"]))["pose"] == json.loads((stage / w["staged"]).read_bytes())["pose"]


def test_worker_written_results_equal_the_returned_ones(tmp_path):
    from app.batch.cli import run_batch
    from app.batch.executors import LocalEngine

    reqs = [variant(0), BAD_RANGE, variant(1, "constrained"), variant(2), UNREACHABLE, variant(3)]
    study = write_jsonl(tmp_path / "s.jsonl", reqs)
    engine = LocalEngine(2)
    try:
        wrote = run_batch([str(study)], tmp_path / "wrote", engine=engine, progress="none")
        sent = run_batch([str(study)], tmp_path / "sent", engine=engine, progress="none", worker_writes=False)
    finally:
        engine.close()
    assert wrote["ok"] == sent["ok"] == 4 and wrote["failed"] == sent["failed"] == 2
    assert wrote["worker_written"] == 4 and sent["worker_written"] == 0
    same = ("item", "key", "name", "status", "error_code", "error_field", "duration_s", "energy_n2_s",
            "max_force_ratio", "contained", "end_error_m", "engine", "attempts", "request_sha", "file")
    rows_w, rows_s = read_summary(tmp_path / "wrote"), read_summary(tmp_path / "sent")
    assert [[r[c] for c in same] for r in rows_w] == [[r[c] for c in same] for r in rows_s]
    # nothing else in OUTDIR: no staging directory, no partial file
    expected = sorted(["summary.csv"] + [r["file"] for r in rows_w if r["file"]])
    assert _files(tmp_path / "wrote") == _files(tmp_path / "sent") == expected
    for row in rows_w:
        if row["file"]:
            a = json.loads((tmp_path / "wrote" / row["file"]).read_bytes())
            assert_same_plan(a, json.loads((tmp_path / "sent" / row["file"]).read_bytes()), tol=0.0)
            assert_same_plan(a, plan(reqs[int(row["item"])]).to_json_dict())


def test_a_worker_that_dies_while_writing_leaves_no_result_behind(tmp_path):
    """The first task holding item 2 writes its results to the staging directory, then its
    worker dies with the files cut short (what SIGKILL in the middle of a write leaves): those
    files are never reported, the items run again and their results are whole."""
    from app.batch.cli import run_batch

    reqs = [variant(i) for i in range(6)]
    victim = json.dumps(reqs[2])
    study = write_jsonl(tmp_path / "s.jsonl", reqs)
    cut: list[str] = []

    def hook(job):
        requests, stage = job.requests, job.stage
        before = set(os.listdir(stage))
        packed = job.run()
        if victim in (r.strip() for r in requests) and not cut:
            for name in sorted(set(os.listdir(stage)) - before):
                path = Path(stage, name)
                path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
                cut.append(name)
            # at the moment of the crash every result in OUTDIR is whole
            for f in (tmp_path / "out").glob("*.json"):
                assert json.loads(f.read_bytes())["metrics"]["steps"] > 0
            raise WorkerCrashed("a worker died while writing its results")
        return packed

    engine = _InlineEngine(hook)
    res = run_batch([str(study)], tmp_path / "out", engine=engine, progress="none")
    assert cut and engine.hooked.crashes == 1 and res["lost_workers"] == 1
    assert res["ok"] == 6 and res["worker_written"] == 6 and res["all_ok"]
    rows = read_summary(tmp_path / "out")
    assert any(r["attempts"] == "2" for r in rows)
    assert _files(tmp_path / "out") == sorted(["summary.csv"] + [r["file"] for r in rows])
    for r in rows:
        assert_same_plan(json.loads((tmp_path / "out" / r["file"]).read_bytes()),
                         plan(reqs[int(r["item"])]).to_json_dict(), tol=0.0)


def test_workers_without_the_output_directory_send_their_results_back(tmp_path):
    """A cluster where only some workers share OUTDIR: every other task runs where the
    staging directory does not exist; those results travel back and are written here."""
    from app.batch.cli import run_batch

    reqs = [variant(i) for i in range(8)]
    study = write_jsonl(tmp_path / "s.jsonl", reqs)
    calls = [0]

    def hook(job):
        calls[0] += 1
        if calls[0] % 2 == 0:
            job = dataclasses.replace(job, stage=job.stage + "-not-on-this-host")
        return job.run()

    res = run_batch([str(study)], tmp_path / "out", engine=_InlineEngine(hook), progress="none")
    assert res["ok"] == 8 and calls[0] >= 2 and 0 < res["worker_written"] < 8
    rows = read_summary(tmp_path / "out")
    assert _files(tmp_path / "out") == sorted(["summary.csv"] + [r["file"] for r in rows])
    for r in rows:
        assert_same_plan(json.loads((tmp_path / "out" / r["file"]).read_bytes()),
                         plan(reqs[int(r["item"])]).to_json_dict(), tol=0.0)


_MALLOC_PROBE = """
import ctypes, os, sys
from app.batch.cluster import relax_malloc_trim
relaxed = relax_malloc_trim() if sys.argv[1] == "relax" else False
libc = ctypes.CDLL("libc.so.6")
libc.malloc.restype = ctypes.c_void_p
libc.free.argtypes = [ctypes.c_void_p]
def rss():
    return int(open("/proc/self/statm").read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
before = rss()
block = libc.malloc(16 << 20)
ctypes.memset(block, 1, 16 << 20)
libc.free(block)
print(relaxed, rss() - before)
"""


@pytest.mark.skipif(not os.path.exists("/proc/self/statm"), reason="Linux only")
def test_relaxed_malloc_trim_keeps_freed_memory_for_reuse():
    """With MALLOC_TRIM_THRESHOLD_=65536 (what Dask's nanny sets) a freed 16 MB block goes
    back to the system at once; after relax_malloc_trim it stays in the heap for the next
    allocation (the planner's per-step arrays)."""
    pytest.importorskip("distributed")
    out = {}
    for how in ("keep", "relax"):
        r = subprocess.run([sys.executable, "-c", _MALLOC_PROBE, how], capture_output=True, text=True,
                           env={**env(), "MALLOC_TRIM_THRESHOLD_": "65536"}, timeout=120)
        assert r.returncode == 0, r.stderr
        relaxed, grown = r.stdout.split()
        out[how] = (relaxed == "True", int(grown))
    assert not out["keep"][0] and out["keep"][1] < 4 << 20  # returned to the system
    assert out["relax"][0] and out["relax"][1] >= 15 << 20  # kept for reuse


# ---------------------------------------------------------------------------------------
# the CLI

@pytest.fixture(scope="module")
def cli_batch(tmp_path_factory):
    """A directory with two request files and a JSON Lines file of variants and bad items,
    planned by `rangeplan batch` on a 2-process pool."""
    tmp = tmp_path_factory.mktemp("batch")
    inputs = tmp / "in"
    inputs.mkdir()
    (inputs / "a-paper.json").write_text(json.dumps(variant(3)))
    (inputs / "b-constrained.json").write_text(json.dumps(variant(-2, "constrained")))
    (inputs / "notes.txt").write_text("ignored: not a request file")
    study = write_jsonl(tmp / "study.jsonl", [variant(1), BAD_RANGE, "{oops", variant(2, "constrained"),
                                              UNREACHABLE, variant(4)])
    out = tmp / "out"
    r = subprocess.run([*CLI, "batch", str(inputs), str(study), "-o", str(out), "--workers", "2"],
                       capture_output=True, text=True, env=env(), timeout=600)
    return {"tmp": tmp, "inputs": inputs, "study": study, "out": out, "run": r}


def test_cli_batch_plans_every_item_and_reports_the_bad_ones(cli_batch):
    r, out = cli_batch["run"], cli_batch["out"]
    assert r.returncode == 1, r.stderr  # some items failed: exit 1, and the rest are planned
    assert "Traceback" not in r.stderr
    rows = read_summary(out)
    assert [row["key"] for row in rows] == ["a-paper", "b-constrained", "study-000001", "study-000002",
                                           "study-000003", "study-000004", "study-000005", "study-000006"]
    assert [row["item"] for row in rows] == [str(i) for i in range(8)]
    by = {row["key"]: row for row in rows}
    assert by["study-000002"]["status"] == "error" and by["study-000002"]["error_code"] == "invalid_input"
    assert by["study-000002"]["error_field"] == "segments[0].lower"
    assert by["study-000003"]["error_code"] == "invalid_input" and "not valid JSON" in by["study-000003"][
        "error_message"]
    assert by["study-000005"]["error_code"] == "unreachable"
    ok = [row for row in rows if row["status"] == "ok"]
    assert len(ok) == 5
    for row in ok:
        assert row["engine"] == "local" and row["worker"] and int(row["attempts"]) == 1
        assert (out / row["file"]).is_file() and row["file"] == f"{row['key']}.json"
        result = json.loads((out / row["file"]).read_text())
        assert float(row["energy_n2_s"]) == result["metrics"]["energy"]
        assert float(row["duration_s"]) == result["metrics"]["duration_s"]
        assert row["name"] == result["name"]
    assert by["b-constrained"]["contained"] == "true"
    assert _files(out) == sorted(["summary.csv"] + [row["file"] for row in ok])  # and no staging directory left
    # a plain line per item (stderr is not a terminal), then the totals
    item_lines = [ln for ln in r.stderr.splitlines() if ln.startswith("[")]
    assert len(item_lines) == 8
    assert "5 ok, 3 failed of 8" in r.stderr


def test_cli_batch_results_equal_single_plans(cli_batch, tmp_path):
    out = cli_batch["out"]
    for key, request in (("a-paper", variant(3)), ("b-constrained", variant(-2, "constrained")),
                         ("study-000004", variant(2, "constrained"))):
        assert_same_plan(json.loads((out / f"{key}.json").read_text()), single_plan(request, tmp_path))


def test_cli_batch_resume_skips_what_is_done(cli_batch):
    tmp, out = cli_batch["tmp"], cli_batch["out"]
    before = {p.name: p.stat().st_mtime_ns for p in out.glob("*.json")}
    r = subprocess.run([*CLI, "batch", str(cli_batch["inputs"]), str(cli_batch["study"]), "-o", str(out),
                        "--workers", "1"], capture_output=True, text=True, env=env(), timeout=300)
    assert r.returncode == 1 and "(8 already done)" in r.stderr, r.stderr
    assert {p.name: p.stat().st_mtime_ns for p in out.glob("*.json")} == before
    # a changed request and a deleted result are planned again; nothing else
    (cli_batch["inputs"] / "a-paper.json").write_text(json.dumps(variant(5)))
    (out / "study-000006.json").unlink()
    r = subprocess.run([*CLI, "batch", str(cli_batch["inputs"]), str(cli_batch["study"]), "-o", str(out),
                        "--workers", "1", "--progress", "lines", "--no-worker-writes"], capture_output=True, text=True,
                       env=env(), timeout=300)
    planned = [ln.split()[1] for ln in r.stderr.splitlines() if ln.startswith("[")]
    assert sorted(planned) == ["a-paper", "study-000006"], r.stderr
    assert json.loads((out / "a-paper.json").read_text())["name"] == "variant 5 paper"
    rows = read_summary(out)
    assert len(rows) == 8 and sum(r_["status"] == "ok" for r_ in rows) == 5
    assert _files(out) == sorted(["summary.csv"] + [r_["file"] for r_ in rows if r_["file"]])
    del tmp


def test_cli_batch_usage_errors_exit_2(tmp_path):
    for args, needle in ((["/nonexistent/x.json"], "no such file"),
                         ([str(tmp_path)], "no *.json"),
                         ([str(TABLE1_FILE), "--workers", "0"], "--workers must be >= 1"),
                         ([str(TABLE1_FILE), "--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "drop one"),
                         ([str(TABLE1_FILE), "--scheduler", "tcp://127.0.0.1:1"], "cannot reach the Dask scheduler")):
        r = subprocess.run([*CLI, "batch", *args, "-o", str(tmp_path / "o")], capture_output=True, text=True,
                           env=env(), timeout=120)
        assert r.returncode == 2, (args, r.stderr)
        assert needle in r.stderr and "Traceback" not in r.stderr, r.stderr


TABLE1_FILE = Path(__file__).resolve().parents[1] / "app" / "static" / "examples" / "table1.json"


@pytest.mark.slow
@pytest.mark.parametrize("limit", [[], ["--timeout", "60"]], ids=["no-limit", "time-limited"])
def test_cli_batch_ctrl_c_keeps_finished_results_and_resumes(tmp_path, limit):
    # time-limited: each item runs in a planning process of its worker, which the terminal's
    # SIGINT reaches too; it must not turn the items in flight into errors (resume skips errors)
    study = write_jsonl(tmp_path / "s.jsonl", [variant(i % 5, "constrained") for i in range(40)])
    out = tmp_path / "out"
    # SIGINT at its default in the batch, as in a terminal: a test run started in the background
    # of a non-interactive shell (`make test &`) ignores SIGINT, and so would the batch
    proc = subprocess.Popen([*CLI, "batch", str(study), "-o", str(out), "--workers", "2", "--progress", "lines",
                             *limit], stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, env=env(),
                            start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    seen = 0
    assert proc.stderr is not None
    for line in proc.stderr:
        if line.startswith("["):
            seen += 1
            if seen == 4:
                break
    os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C on a terminal does: the whole process group
    rest = proc.stderr.read()
    assert proc.wait(60) == 130, rest
    assert "interrupted" in rest and "Traceback" not in rest
    rows = read_summary(out)
    assert 4 <= len(rows) < 40
    assert all(r["status"] == "ok" and (out / r["file"]).is_file() for r in rows)
    assert len(list(out.glob("*.json"))) == len(rows)  # no partial result file left behind
    assert not list(out.glob(".rangeplan-staging-*"))  # nor what the killed workers had staged
    r = subprocess.run([*CLI, "batch", str(study), "-o", str(out), "--workers", "2", "--progress", "lines", *limit],
                       capture_output=True, text=True, env=env(), timeout=600)
    assert r.returncode == 0, r.stderr
    planned = [ln for ln in r.stderr.splitlines() if ln.startswith("[")]
    assert len(planned) == 40 - len(rows)
    assert len(read_summary(out)) == 40


@pytest.mark.slow
def test_local_worker_killed_mid_batch_loses_no_item(tmp_path):
    from app.batch.cli import run_batch
    from app.batch.executors import LocalEngine

    study = write_jsonl(tmp_path / "s.jsonl", [variant(i % 7, "constrained") for i in range(24)])
    engine = LocalEngine(2)
    killed: list[int] = []

    def killer():
        while not killed:
            rows = (tmp_path / "out" / "summary.csv")
            if rows.exists() and len(rows.read_text().splitlines()) >= 4 and engine.pids():
                pid = engine.pids()[0]
                os.kill(pid, signal.SIGKILL)
                killed.append(pid)
            time.sleep(0.05)

    t = threading.Thread(target=killer, daemon=True)
    t.start()
    try:
        res = run_batch([str(study)], tmp_path / "out", engine=engine, progress="none")
    finally:
        engine.close()
    assert killed and res["lost_workers"] >= 1 and res["resubmitted"] >= 1
    rows = read_summary(tmp_path / "out")
    assert len(rows) == 24 and all(r["status"] == "ok" for r in rows)
    assert any(r["attempts"] == "2" for r in rows)
    assert killed[0] not in {int(r["worker"].rsplit(":", 1)[1]) for r in rows if r["attempts"] == "2"}
    ref = plan(variant(3, "constrained")).to_json_dict()
    assert_same_plan(json.loads((tmp_path / "out" / "s-000004.json").read_text()), ref)
    # the workers wrote the results; whatever the killed one had staged is gone, every file is whole
    assert res["worker_written"] == 24
    assert _files(tmp_path / "out") == sorted(["summary.csv"] + [r["file"] for r in rows])
    for r in rows:
        req = variant(int(r["item"]) % 7, "constrained")
        assert json.loads((tmp_path / "out" / r["file"]).read_bytes())["name"] == req["name"]


# ---------------------------------------------------------------------------------------
# the HTTP API

@pytest.fixture(scope="module")
def api(tmp_path_factory):
    store = Store(tmp_path_factory.mktemp("data"))
    app = create_app(store, workers=1, timeout_s=120)
    with api_client(app) as c:
        yield c


def wait_done(client, batch_id: str, timeout: float = 300) -> dict:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        p = client.get(f"/v1/batches/{batch_id}").json()
        if p["state"] in ("done", "cancelled"):
            return p
        time.sleep(0.2)
    raise AssertionError(f"batch {batch_id} did not finish: {p}")


def test_api_batch_runs_in_the_background_and_streams_results_in_order(api):
    reqs = [variant(0), BAD_RANGE, variant(1, "constrained"), UNREACHABLE, variant(2)]
    r = api.post("/v1/batches", json={"requests": reqs, "name": "study"})
    assert r.status_code == 202, r.text
    body = r.json()
    assert r.headers["location"] == f"/v1/batches/{body['id']}"
    assert body["total"] == 5 and body["state"] in ("queued", "running") and body["name"] == "study"
    p = wait_done(api, body["id"])
    assert p["state"] == "done" and p["done"] == 5 and p["ok"] == 3 and p["failed"] == 2
    assert p["running"] == 0 and p["pending"] == 0 and p["rate_per_s"] > 0
    lines = api.get(f"/v1/batches/{body['id']}/results")
    assert lines.headers["content-type"].startswith("application/x-ndjson")
    items = [json.loads(ln) for ln in lines.text.splitlines()]
    assert [it["item"] for it in items] == [0, 1, 2, 3, 4]
    assert [it["status"] for it in items] == ["ok", "error", "ok", "error", "ok"]
    assert items[1]["error"]["code"] == "invalid_input" and items[1]["error"]["field"] == "segments[0].lower"
    assert items[3]["error"]["code"] == "unreachable"
    for i, req in ((0, variant(0)), (2, variant(1, "constrained")), (4, variant(2))):
        single = api.post("/v1/plan", json=req)
        assert single.status_code == 200
        assert_same_plan(items[i]["result"], single.json())
        assert items[i]["engine"] == "local" and items[i]["summary"]["energy"] == single.json()["metrics"]["energy"]
    csv_text = api.get(f"/v1/batches/{body['id']}/results?format=csv").text.splitlines()
    assert csv_text[0].startswith("item,key,name,status,error_code")
    assert [ln.split(",")[3] for ln in csv_text[1:]] == ["ok", "error", "ok", "error", "ok"]
    assert any(b["id"] == body["id"] for b in api.get("/v1/batches").json())


def test_api_batch_accepts_json_lines_and_waits_on_request(api):
    text = "\n".join(json.dumps(variant(i)) for i in range(3)) + "\n"
    r = api.post("/v1/batches?name=lines", content=text, headers={"Content-Type": "application/x-ndjson"})
    assert r.status_code == 202 and r.json()["total"] == 3 and r.json()["name"] == "lines"
    items = [json.loads(ln) for ln in api.get(f"/v1/batches/{r.json()['id']}/results?wait=true").text.splitlines()]
    assert [it["status"] for it in items] == ["ok"] * 3


@pytest.mark.parametrize("kwargs, status, code, field", [
    ({"content": b"{not json", "headers": {"Content-Type": "application/json"}}, 422, "invalid_input", None),
    ({"json": {"name": "x"}}, 422, "invalid_input", "requests"),
    ({"json": {"requests": []}}, 422, "invalid_input", "requests"),
    ({"json": [TABLE1]}, 422, "invalid_input", None),
    ({"json": {"requests": [TABLE1], "extra": 1}}, 422, "invalid_input", "extra"),
    ({"json": {"requests": [TABLE1], "name": 5}}, 422, "invalid_input", "name"),
    ({"content": b"\n\n", "headers": {"Content-Type": "application/x-ndjson"}}, 422, "invalid_input", "requests"),
    ({"json": {"requests": [TABLE1, [None, None]]}}, 422, "invalid_input", "requests[1]"),  # not a request at all
])
def test_api_bad_batch_is_a_clear_422(api, kwargs, status, code, field):
    r = api.post("/v1/batches", **kwargs)
    assert r.status_code == status, r.text
    err = r.json()["error"]
    assert err["code"] == code and err["field"] == field and err["message"]


def test_api_unknown_batch_is_404(api):
    for method, path in (("get", "/v1/batches/nope"), ("get", "/v1/batches/nope/results"),
                         ("get", "/v1/batches/nope/results?format=csv"), ("post", "/v1/batches/nope/cancel"),
                         ("delete", "/v1/batches/nope")):
        r = getattr(api, method)(path)
        assert r.status_code == 404 and r.json()["error"]["code"] == "not_found"


def test_api_batch_limits(tmp_path):
    app = create_app(Store(tmp_path), workers=1)
    with api_client(app) as c:
        svc = app.state.batches
        svc.max_items, svc.max_queue = 3, 5
        r = c.post("/v1/batches", json={"requests": [TABLE1] * 4})
        assert r.status_code == 422 and r.json()["error"]["code"] == "too_large"
        assert r.json()["error"]["field"] == "requests"
        svc._stop.set()  # the dispatcher stops: what is queued now stays queued
        svc._wake.set()
        svc._thread.join(10)
        svc.store.create([json.dumps(TABLE1)] * 3)
        svc.max_queue = 4
        r = c.post("/v1/batches", json={"requests": [TABLE1] * 2})
        assert r.status_code == 503 and r.json()["error"]["code"] == "busy" and r.headers["retry-after"]
        assert c.post("/v1/batches", json={"requests": [TABLE1]}).status_code == 202  # 3 + 1 <= 4


def test_api_batch_items_have_the_bounds_of_a_single_plan(tmp_path, monkeypatch):
    """A batch item is refused for too much work as POST /v1/plan refuses it on the same
    server (the same estimate, limit, code, field and message), in well under a second and
    without planning; the other items plan. (The server's jobs have the same 5 s limit: a
    plan over it is refused, not made a job.)"""
    monkeypatch.setenv("RANGEPLAN_JOB_TIMEOUT_S", "5")
    heavy = {**TABLE1, "settings": {"mode": "constrained", "N": 150, "backend": "reference"}}
    app = create_app(Store(tmp_path), workers=1, timeout_s=5.0)
    with api_client(app) as c:
        single = c.post("/v1/plan", json=heavy)
        assert single.status_code == 422 and single.json()["error"]["code"] == "too_much_work"
        assert app.state.batches.timeout_s == 5.0
        bid = c.post("/v1/batches", json={"requests": [heavy, TABLE1]}).json()["id"]
        items = [json.loads(ln) for ln in c.get(f"/v1/batches/{bid}/results?wait=true").text.splitlines()]
    assert [it["status"] for it in items] == ["error", "ok"]
    assert items[0]["error"] == single.json()["error"]
    assert items[0]["error"]["field"] == "settings.N" and "limit of 5 s" in items[0]["error"]["message"]


@pytest.mark.serial  # a bound of 1 s
def test_plan_item_refuses_too_much_work_before_planning():
    heavy = {**TABLE1, "settings": {"mode": "constrained", "N": 150, "backend": "reference"}}
    t0 = time.perf_counter()
    out = plan_item(heavy, timeout_s=5.0)
    assert time.perf_counter() - t0 < 1.0 and out["status"] == "error" and out["payload"] is None
    assert out["error"]["code"] == "too_much_work" and out["error"]["field"] == "settings.N"
    assert plan_item(TABLE1, timeout_s=5.0)["status"] == "ok"  # within the estimate: planned


@pytest.mark.slow
def test_local_workers_have_the_api_workers_memory_cap():
    """A batch worker capped at 700 MiB (~0.5 GiB is the interpreter with the planner) given
    the largest corridor the schema accepts (~0.8 GiB) answers the API's too_much_memory, and
    plans the next item."""
    from app.batch.engine import BatchChunkJob, chunk_outcomes
    from app.batch.executors import LocalEngine
    from tests.test_api import long_corridor

    engine = LocalEngine(1, memory_mb=700)
    try:
        job = BatchChunkJob((long_corridor(), TABLE1), "none", 120.0, engine.item_memory_mb, None, engine.name)
        out, nxt = chunk_outcomes(engine.executor.submit(job, 0.0).result(300))
        assert out["status"] == "error" and out["error"]["code"] == "too_much_memory", out["error"]
        assert "700 MiB" in out["error"]["message"] and "RANGEPLAN_WORKER_MEMORY_MB" in out["error"]["message"]
        assert nxt["status"] == "ok" and nxt["pid"] == out["pid"]  # the chunk's worker lives on
    finally:
        engine.close(cancel=True)


@pytest.mark.slow
def test_api_cancel_keeps_finished_results_and_delete_deletes(api):
    r = api.post("/v1/batches", json={"requests": [variant(i % 5, "constrained") for i in range(30)]})
    bid = r.json()["id"]
    deadline = time.monotonic() + 120
    while api.get(f"/v1/batches/{bid}").json()["ok"] < 2 and time.monotonic() < deadline:
        time.sleep(0.1)
    p = api.post(f"/v1/batches/{bid}/cancel").json()
    assert p["state"] == "cancelled" and p["cancelled"] > 0 and p["ok"] >= 2
    time.sleep(1.0)
    after = api.get(f"/v1/batches/{bid}").json()
    assert after["ok"] == p["ok"] and after["running"] == 0 and after["pending"] == 0  # nothing more ran
    items = [json.loads(ln) for ln in api.get(f"/v1/batches/{bid}/results").text.splitlines()]
    assert len(items) == 30 and sum(it["status"] == "ok" for it in items) == p["ok"]
    assert {it["status"] for it in items} <= {"ok", "cancelled"}
    assert api.post(f"/v1/batches/{bid}/cancel").json()["ok"] == p["ok"]  # cancelling again changes nothing
    assert api.delete(f"/v1/batches/{bid}").status_code == 204
    for path in (f"/v1/batches/{bid}", f"/v1/batches/{bid}/results"):
        assert api.get(path).status_code == 404
    assert all(b["id"] != bid for b in api.get("/v1/batches").json())
    assert api.delete(f"/v1/batches/{bid}").status_code == 404


@pytest.mark.slow
def test_api_batch_survives_a_restart_and_never_takes_the_interactive_pool(tmp_path):
    store_dir = tmp_path / "data"
    n = 320  # ~17 ms each: long enough to be mid-batch when the server stops
    reqs = [variant(i % 5, "constrained") for i in range(n)]
    app = create_app(Store(store_dir), workers=1)
    with api_client(app) as c:
        bid = c.post("/v1/batches", json={"requests": reqs}).json()["id"]
        deadline = time.monotonic() + 120
        while c.get(f"/v1/batches/{bid}").json()["ok"] < 2 and time.monotonic() < deadline:
            time.sleep(0.1)
        # a single plan meanwhile: served by the interactive pool, not queued behind the batch
        t0 = time.perf_counter()
        single = c.post("/v1/plan", json=TABLE1)
        assert single.status_code == 200 and time.perf_counter() - t0 < 30
        svc = app.state.batches
        batch_pids = svc.engine.pids()
        assert batch_pids and all(os.getpriority(os.PRIO_PROCESS, pid) >= 10 for pid in batch_pids)
        pool_pids = [w.pid for w in app.state.pool._workers]
        assert all(pid is not None for pid in pool_pids)
        assert not set(batch_pids) & set(pool_pids)
        # interactive workers run below the server (WORKER_NICE: it answers /ready while they plan),
        # batch workers below the interactive ones (a batch yields to single plans)
        server = os.getpriority(os.PRIO_PROCESS, 0)
        assert all(os.getpriority(os.PRIO_PROCESS, pid) == server + WORKER_NICE for pid in pool_pids)
        assert all(os.getpriority(os.PRIO_PROCESS, b) > os.getpriority(os.PRIO_PROCESS, p)
                   for b in batch_pids for p in pool_pids)
        before = c.get(f"/v1/batches/{bid}").json()
    assert before["state"] == "running" and before["done"] < n
    # the server stopped mid-batch; a new one on the same store finishes it
    app2 = create_app(Store(store_dir), workers=1)
    with api_client(app2) as c:
        p = wait_done(c, bid)
        assert p["state"] == "done" and p["ok"] == n
        items = [json.loads(ln) for ln in c.get(f"/v1/batches/{bid}/results").text.splitlines()]
    assert [it["item"] for it in items] == list(range(n)) and all(it["status"] == "ok" for it in items)
    ref = plan(reqs[7]).to_json_dict()
    assert_same_plan(items[7]["result"], ref)


def test_run_batch_inline_writes_csv_or_only_the_summary(tmp_path):
    from app.batch.cli import run_batch

    study = write_jsonl(tmp_path / "s.jsonl", [variant(0), variant(1)])
    res = run_batch([str(study)], tmp_path / "csv", fmt="csv", inline=True, progress="none")
    assert res["ok"] == 2 and res["engine"] == "inline" and res["all_ok"]
    rows = read_summary(tmp_path / "csv")
    assert [r["file"] for r in rows] == ["s-000001.csv", "s-000002.csv"]
    assert all(r["engine"] == "inline" and r["worker"].endswith(f":{os.getpid()}") for r in rows)
    header = (tmp_path / "csv" / "s-000001.csv").read_text().splitlines()[0]
    assert header.startswith("time_s,x_m,y_m,psi_rad")
    res = run_batch([str(study)], tmp_path / "none", fmt="none", inline=True, progress="none")
    assert res["ok"] == 2 and [p.name for p in (tmp_path / "none").iterdir()] == ["summary.csv"]
    assert all(r["file"] == "" and r["status"] == "ok" for r in read_summary(tmp_path / "none"))


def test_progress_bar_counts_done_failed_and_rate():
    import io

    from app.batch.progress import RichProgress, make_progress

    buf = io.StringIO()
    bar = make_progress("bar", 3, 1, buf)
    assert isinstance(bar, RichProgress)
    bar.start("test engine")
    bar.item("a", {"status": "ok", "summary": {"duration_s": 1.0, "energy": 2.0, "max_force_ratio": 0.1,
                                               "compute_ms": 3.0}})
    bar.item("b", {"status": "error", "error": {"code": "unreachable", "message": "too far", "field": "segments[1]"}})
    bar.close()
    assert (bar.done, bar.failed) == (3, 1)
    text = buf.getvalue()
    assert "b error unreachable: segments[1]: too far" in text and "3/3" in text
    assert make_progress("auto", 1, 0, io.StringIO()).__class__.__name__ == "Progress"  # not a terminal: lines


def test_batch_counters_count_what_they_say(tmp_path):
    """``running`` is what the workers plan now (at most their slots; items sent ahead wait,
    as ``pending``), ``rate_per_s`` counts planned items, not cancellations, and a resumed
    CLI batch's bar starts at the items already done."""
    import io
    from types import SimpleNamespace

    from app.batch.progress import RichProgress
    from app.batch.service import BatchService
    from app.batch.store import BatchStore

    service = BatchService.__new__(BatchService)  # only its engine matters here
    service.engine = SimpleNamespace(slots=1)
    out = service.at_workers({"running": 43, "pending": 100, "done": 0})
    assert (out["running"], out["pending"]) == (1, 142)
    store = BatchStore(tmp_path / "b.sqlite3")
    try:
        batch_id = store.create([json.dumps({"name": f"r{i}"}) for i in range(6)], "rate")["id"]
        claimed = store.claim(6)
        time.sleep(0.02)
        seq = store.seq_of(batch_id)
        store.save([(seq, item, {"status": "ok", "summary": {}}) for (_, _, item, _) in claimed[:2]])
        store.cancel(batch_id)  # 4 cancelled at once: not 4 more items per second
        p = store.progress(batch_id)
        assert p["ok"] == 2 and p["cancelled"] == 4
        assert p["rate_per_s"] is not None and p["rate_per_s"] * p["elapsed_s"] == pytest.approx(2.0)
    finally:
        store.close()
    bar = RichProgress(202, 0, io.StringIO())
    for _ in range(11):
        bar.skip()  # the items a resumed run finds done, before its first plan
    bar.start("test")
    assert bar.bar.tasks[0].completed == 11 and bar.done == 11 and bar.new == 0
    bar.close()


# ---------------------------------------------------------------------------------------
# contour items (G-code programs) beside plan items

def test_request_kind_tells_a_contour_request_by_its_program():
    from app.batch.engine import request_kind

    assert request_kind({"program": "G1 X1\n"}) == "contour" and request_kind(json.dumps({"program": ""})) == "contour"
    assert request_kind(TABLE1) == "plan" and request_kind(json.dumps(TABLE1)) == "plan"
    # "program" inside a string (a name) is no contour request; neither is text that is no JSON
    assert request_kind(json.dumps({**TABLE1, "name": 'the "program" study'})) == "plan"
    assert request_kind(b'{"program": ') == "plan"


def test_plan_item_contours_a_program_as_post_v1_contour():
    from tests.batch_support import assert_same_contour, contour_items

    good, _, _, bad = contour_items()
    out = plan_item(json.dumps(good))
    assert out["status"] == "ok" and out["kind"] == "contour" and out["name"] == "small", out["error"]
    result = json.loads(bytes(out["payload"]))
    assert_same_contour(result, good)
    s = out["summary"]
    assert s["max_deviation_m"] == result["contour"]["max_deviation_m"] <= s["tolerance_m"] == 5e-5
    assert s["cycle_time_s"] == result["contour"]["cycle_time_s"] and s["passes"] == 1
    refused = plan_item(bad)
    assert refused["status"] == "error" and refused["kind"] == "contour"
    assert refused["error"]["code"] == "invalid_input" and refused["error"]["field"] == "program"
    assert "line 11" in refused["error"]["message"] and "G41" in refused["error"]["message"]
    invalid = plan_item({"program": good["program"], "tolerance_m": -1})
    assert invalid["error"]["code"] == "invalid_input" and invalid["error"]["field"] == "tolerance_m"


@pytest.mark.slow
def test_run_batch_contours_beside_plans_on_the_local_pool_and_resumes(tmp_path):
    from app.batch.cli import run_batch
    from tests.batch_support import assert_same_contour, contour_items

    contours = contour_items()
    reqs = [variant(0), contours[0], variant(1, "constrained"), contours[1], contours[3], contours[2]]
    study = write_jsonl(tmp_path / "mixed.jsonl", reqs)
    out = tmp_path / "out"
    res = run_batch([str(study)], out, workers=2, progress="none", timeout_s=120)
    assert (res["ok"], res["failed"], res["total"]) == (5, 1, 6), res
    rows = {r["key"]: r for r in read_summary(out)}
    assert [rows[f"mixed-{i:06d}"]["kind"] for i in range(1, 7)] == ["plan", "contour", "plan", "contour",
                                                                      "contour", "contour"]
    assert rows["mixed-000005"]["error_code"] == "invalid_input" and rows["mixed-000005"]["error_field"] == "program"
    for i in (2, 4, 6):
        row = rows[f"mixed-{i:06d}"]
        result = json.loads((out / row["file"]).read_text())
        assert_same_contour(result, reqs[i - 1])
        assert float(row["max_deviation_m"]) == result["contour"]["max_deviation_m"] <= float(row["tolerance_m"])
        assert float(row["cycle_time_s"]) == result["contour"]["cycle_time_s"] and row["engine"] == "local"
    assert rows["mixed-000001"]["max_deviation_m"] == "" and rows["mixed-000001"]["duration_s"] != ""
    # resume: every item done (the refused program too: the request's fault) is skipped
    mtimes = {p.name: p.stat().st_mtime_ns for p in out.glob("*.json")}
    again = run_batch([str(study)], out, workers=1, progress="none", timeout_s=120)
    assert (again["skipped"], again["ok"], again["failed"]) == (6, 0, 0), again
    assert {p.name: p.stat().st_mtime_ns for p in out.glob("*.json")} == mtimes
    # a changed program is contoured again, the rest skipped
    reqs[3] = {**contours[1], "tolerance_m": 4e-5}
    write_jsonl(study, reqs)
    third = run_batch([str(study)], out, workers=1, progress="none", timeout_s=120)
    assert (third["skipped"], third["ok"]) == (5, 1), third
    assert_same_contour(json.loads((out / "mixed-000004.json").read_text()), reqs[3])
    assert len(read_summary(out)) == 6


@pytest.mark.slow
def test_api_batch_contours_beside_plans(api):
    from tests.batch_support import assert_same_contour, contour_items

    contours = contour_items()
    reqs = [contours[0], variant(2), contours[3]]
    r = api.post("/v1/batches", json={"requests": reqs})
    assert r.status_code == 202, r.text
    bid = r.json()["id"]
    items = [json.loads(ln) for ln in api.get(f"/v1/batches/{bid}/results?wait=true").text.splitlines()]
    assert [(it["kind"], it["status"]) for it in items] == [("contour", "ok"), ("plan", "ok"), ("contour", "error")]
    assert_same_contour(items[0]["result"], contours[0])
    assert items[0]["summary"]["max_deviation_m"] == items[0]["result"]["contour"]["max_deviation_m"]
    assert items[2]["error"]["code"] == "invalid_input" and items[2]["error"]["field"] == "program"
    csv_rows = api.get(f"/v1/batches/{bid}/results?format=csv").text.splitlines()
    assert csv_rows[0].split(",")[-6:] == ["kind", "max_deviation_m", "tolerance_m", "cycle_time_s", "cut_time_s",
                                           "passes"]
    assert csv_rows[1].split(",")[20] == "contour" and csv_rows[2].split(",")[20] == "plan"
