"""The certification harness itself (issue 31 goal 1: a 10 000-case run in slices): the checker
reads a result's arrays directly and finds what it found from the result's JSON; the CPU
profile counts every second once; ``benchmarks/certify.py --resume`` runs a case once across
sittings and ``--summary`` sums the file honestly."""

from __future__ import annotations

import copy
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from planner import plan
from tests.certify_support import CPU, check_plan, cpu_spent
from tests.support import ROOT, TABLE1, with_settings

LAYOUT = {"robot": "tri-slide", "layout": {
    "bounds": {"lower": [-0.06, -0.05], "upper": [0.06, 0.05]},
    "obstacles": [{"type": "polygon", "points": [[-0.01, -0.02], [0.02, -0.01], [0.0, 0.02]]}],
    "clearance": 0.002, "cell": {"shape": "triangle", "size": 0.01},
    "start": [-0.045, -0.03, 0.0], "end": [0.045, 0.03, 0.0]}}


def _both(request: dict, result, segments) -> tuple:
    """The checker's verdict from the result object (its arrays read directly) and from the
    result's whole JSON (what it read before)."""
    direct = check_plan(request, result, segments)
    via_json = check_plan(request, json.loads(result.model_dump_json()), segments)
    return direct, via_json


@pytest.mark.parametrize("request_", [TABLE1, with_settings(TABLE1, mode="paper"),
                                      with_settings(TABLE1, force_rate_n_s=400.0, Ts=0.005), LAYOUT],
                         ids=["table1", "table1-paper", "table1-rate", "layout-triangles"])
def test_the_checker_finds_the_same_from_the_arrays_as_from_the_json(request_):
    """Every figure the checker recomputes and every problem it names are the same whether it
    reads the result's arrays or the result's JSON parsed back (a float64 array and its JSON
    list hold the same numbers); for a layout with the corridor's exact cell polygons read from
    the result, and for results made wrong (a sample moved out of the corridor, a force over
    its limit), which both readings catch."""
    result = plan(request_)
    segs = request_.get("segments")  # a layout: the result's corridor (polygons) is read
    direct, via_json = _both(request_, result, segs)
    assert direct.ok and via_json.ok, (direct.problems, via_json.problems)
    assert direct.figures == via_json.figures
    if request_.get("layout") is not None:
        assert any(s.polygon is not None for s in result.corridor.segments or [])
    bad = result.model_copy(deep=True)
    bad.pose[len(bad.pose) // 2, 1] += 0.03
    bad.drives.force[3, 0] = 5.0 * float(np.max(np.abs(bad.drives.force)))
    direct, via_json = _both(request_, bad, segs)
    assert not direct.ok and direct.problems == via_json.problems
    assert direct.figures == via_json.figures
    assert any("drives.length" in p for p in direct.problems)  # the moved sample's legs no longer agree


def test_every_cpu_second_is_counted_once_in_its_innermost_category():
    """:func:`cpu_spent` partitions the CPU time of nested blocks: the categories sum to the
    outermost block's time, and a block's time is not counted again in the one around it."""

    def spin(seconds: float) -> None:
        t = time.process_time()
        while time.process_time() - t < seconds:
            sum(range(1000))

    CPU.clear()
    t0 = time.process_time()
    with cpu_spent("outer"):
        spin(0.01)
        with cpu_spent("inner") as slot:
            spin(0.05)
            slot[0] = "inner renamed"  # a plan's category is named by its outcome, once known
            with cpu_spent("innermost"):
                spin(0.02)
            with cpu_spent(": part"):  # a part of the block around it, under its final name
                spin(0.02)
        spin(0.01)
    total = time.process_time() - t0
    assert set(CPU) == {"outer", "inner renamed", "innermost", "inner renamed: part"}
    assert sum(CPU.values()) == pytest.approx(total, abs=2e-3)
    assert 0.05 <= CPU["inner renamed"] < 0.05 + 0.015 and CPU["innermost"] >= 0.02
    assert CPU["inner renamed: part"] >= 0.02
    assert 0.02 <= CPU["outer"] < 0.035  # its own 2 x 10 ms, not the 90 ms inside it
    CPU.clear()


CERTIFY = [sys.executable, str(ROOT / "benchmarks" / "certify.py")]


def _certify(*args: str) -> str:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1"}
    r = subprocess.run([*CERTIFY, *args], capture_output=True, text=True, env=env, timeout=300, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-2000:]
    return r.stdout


def _records(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


@pytest.mark.slow
def test_resume_runs_each_case_once_across_sittings_and_the_summary_sums_the_file(tmp_path):
    """Two sittings of ``--resume`` (cases 0-4, then 0-7) and a cut last line (a sitting
    stopped mid-write): each case of the run is in the file once for this code, the cut case
    is run again, the second sitting skips what the first did, records of other code or
    another seed are kept but not summed with these, and ``--summary`` counts 8 cases.
    (A compute limit of 1 us refuses every case up front, ``too_much_work``: no planning.)"""
    f = tmp_path / "run.jsonl"
    base = ["--users", "--seed", "31", "--limit", "1e-6", "--workers", "1", "--minutes", "3", "--resume", str(f)]
    _certify(*base, "--cases", "5")
    first = _records(f)
    assert sorted(r["index"] for r in first) == [0, 1, 2, 3, 4]
    run = first[0]["run"]
    assert all(r["run"] == run for r in first) and run["seed"] == 31 and run["users"]
    assert all(r["modes"]["constrained"]["outcome"] in ("too_much_work", "too_large") for r in first)
    # a sitting stopped while writing case 4's line; a record of other code, one of another seed
    lines = f.read_text().splitlines()
    cut = next(i for i, line in enumerate(lines) if json.loads(line)["index"] == 4)
    other_code = copy.deepcopy(json.loads(lines[0]))
    other_code["run"]["code"] = "0" * 16
    other_code["index"] = 6
    other_seed = copy.deepcopy(json.loads(lines[0]))
    other_seed["run"]["seed"] = 32
    kept = [line for i, line in enumerate(lines) if i != cut]
    f.write_text("\n".join([*kept, json.dumps(other_code), json.dumps(other_seed), lines[cut][:40]]))
    out = _certify(*base, "--cases", "8")
    assert "5 already in" not in out and "4 already in" in out, out
    mine = [r for r in _records_loose(f) if r["run"] == run]
    assert sorted(r["index"] for r in mine) == list(range(8))  # case 4 again, 5-7 new, none twice
    summary = _certify("--summary", str(f))
    rows = [line for line in summary.splitlines() if line.startswith("| 3")]
    assert len(rows) == 3, summary  # this run, its other-code record, the other seed
    this = next(r for r in rows if "(this code)" in r)
    assert this.split("|")[4].strip() == "8"
    assert sum(int(r.split("|")[4]) for r in rows) == 10


def _records_loose(path: Path) -> list[dict]:
    """The file's records, a cut line skipped (as ``--resume`` and ``--summary`` read it)."""
    out = []
    for line in path.read_text().splitlines():
        try:
            out.append(json.loads(line))
        except json.JSONDecodeError:
            continue
    return out


def test_summary_sets_two_codes_runs_of_the_same_cases_side_by_side(tmp_path):
    """``--summary before.jsonl after.jsonl``: the cases both runs hold, which of them changed
    outcome or checker verdict (named), which changed only their refusal message (the advice
    search is bounded in wall time), and their CPU either side."""

    def rec(code: str, i: int, outcome: str, message: str, cpu: float) -> str:
        run = {"users": True, "seed": 31, "limit": 30.0, "code": code}
        mode = {"outcome": outcome, "problem": None, "seconds": cpu, "estimate": 1.0, "speed": 1.0,
                "message": message}
        return json.dumps({"run": run, "index": i, "modes": {"constrained": mode}, "cpu_s": cpu, "cpu": {},
                           "start_s": None, "case": None})

    before, after = tmp_path / "before.jsonl", tmp_path / "after.jsonl"
    before.write_text("\n".join([rec("a" * 16, 0, "ok", "", 2.0), rec("a" * 16, 1, "infeasible", "x; 2x plans", 4.0),
                                 rec("a" * 16, 2, "ok", "", 1.0), rec("a" * 16, 3, "ok", "", 9.0)]) + "\n")
    after.write_text("\n".join([rec("b" * 16, 0, "ok", "", 1.0), rec("b" * 16, 1, "infeasible", "x", 3.0),
                                rec("b" * 16, 2, "infeasible", "y", 1.0)]) + "\n")
    out = _certify("--summary", str(before), str(after))
    line = next(x for x in out.splitlines() if x.startswith("code aaaa"))
    assert "3 cases in both" in line and "differs in 1 [2]" in line and "message differs in 2 [1, 2]" in line, line
    assert "CPU 7 -> 5 s" in line, line
