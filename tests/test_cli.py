"""The command line: plan to JSON and CSV; bad input exits 2 with one line."""

import csv
import json
import subprocess
import sys

import numpy as np
import pytest

from tests.support import TABLE1_PATH as TABLE1

CLI = [sys.executable, "-m", "app.cli"]


def run(*args, stdin=None):
    return subprocess.run([*CLI, *args], capture_output=True, text=True, input=stdin, timeout=120)


def test_plan_json_and_csv_agree(tmp_path):
    out_json, out_csv = tmp_path / "t.json", tmp_path / "t.csv"
    assert run("plan", str(TABLE1), "-o", str(out_json)).returncode == 0
    assert run("plan", str(TABLE1), "-o", str(out_csv)).returncode == 0
    result = json.loads(out_json.read_text())
    rows = list(csv.reader(out_csv.open()))
    header, data = rows[0], np.array(rows[1:], dtype=float)
    assert header[:4] == ["time_s", "x_m", "y_m", "psi_rad"]
    assert all(h.endswith(("_s", "_m", "_rad", "_m_s", "_rad_s", "_m_s2", "_rad_s2", "_n")) for h in header)
    assert len(data) == len(result["time"])
    assert np.allclose(data[:, 1:4], result["pose"], rtol=0, atol=0)
    assert np.allclose(data[:, header.index("leg3_force_n")], np.array(result["drives"]["force"])[:, 2])


@pytest.mark.parametrize("content, needle", [
    ("{not json", "not valid JSON"),
    ('{"segments": [{"lower": [0, 0, 0], "upper": [-1, 0, 0]}, {"lower": [0, 0, 0], "upper": [0, 0, 0]}]}',
     "segments[0].lower"),
    ('{"segments": [{"lower": [0, 0, "a"], "upper": [0, 0, 0]}, {"lower": [0, 0, 0], "upper": [0, 0, 0]}]}',
     "segments[0].lower[2]"),
    ('{"segments": [{"lower": [0, 0, 0], "upper": [0, 0, 0]}, {"lower": [0.3, 0, 0], "upper": [0.3, 0, 0]}]}',
     "unreachable"),
    ('{"segments": [{"lower": [0, 0, 0], "upper": [0, 0, 0]}, {"lower": [0, 0, 0], "upper": [0, 0, 0]}], '
     '"settings": {"Ts": -1}}', "settings.Ts"),
])
def test_bad_input_exits_2_with_one_line(tmp_path, content, needle):
    f = tmp_path / "bad.json"
    f.write_text(content)
    r = run("plan", str(f))
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0] and "Traceback" not in r.stderr
    assert r.stdout == ""


def test_missing_file_exits_2():
    r = run("plan", "/nonexistent/x.json")
    assert r.returncode == 2 and "cannot read" in r.stderr
