"""The command line: plan to JSON and CSV; bad input exits 2 with one line."""

import csv
import json
import subprocess
import sys
from pathlib import Path

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


def test_output_to_a_directory_exits_2(tmp_path):
    r = run("plan", str(TABLE1), "-o", str(tmp_path))
    assert r.returncode == 2 and str(tmp_path) in r.stderr and "cannot write" in r.stderr
    assert "Traceback" not in r.stderr and list(tmp_path.iterdir()) == []


def test_compact_json_is_the_apis_serialisation_and_the_default_indents_it(tmp_path):
    """``--compact`` writes the job's own bytes (what ``POST /v1/plan`` answers); the default is
    the same document indented: one serializer for JSON."""
    compact, pretty = run("plan", str(TABLE1), "--compact"), run("plan", str(TABLE1))
    assert compact.returncode == 0 and pretty.returncode == 0
    assert compact.stdout.count("\n") == 1 and ", " not in compact.stdout[:2000]  # no separator spaces
    a, b = json.loads(compact.stdout), json.loads(pretty.stdout)
    for doc in (a, b):  # the only fields two runs may differ in: the time the plan took
        for k in [k for k in doc["metrics"] if k.endswith("_ms")]:
            del doc["metrics"][k]
    assert a == b and pretty.stdout.startswith('{\n "plan_id": null')


# ---------------------------------------------------------------------------------------
# no hidden processes (issue 34): a command plans in its own process, and a command that is
# stopped never writes its output afterwards

def _ours(marker: str) -> set[int]:
    """Processes whose environment carries ``marker`` (a command and anything it started,
    detached or not: children inherit the environment)."""
    import os
    from pathlib import Path

    found = set()
    for proc in Path("/proc").iterdir():
        if proc.name.isdigit() and int(proc.name) != os.getpid():
            try:
                if f"RANGEPLAN_TEST_MARKER={marker}\0".encode() in (proc / "environ").read_bytes():
                    found.add(int(proc.name))
            except OSError:
                pass
    return found


def _cpu_s(pid: int) -> float:
    """CPU seconds (user + system) ``pid`` has used so far."""
    import os

    fields = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _command_cpu(path, out, marker: str) -> tuple[float, float]:
    """(CPU s, wall s) of ``rangeplan plan PATH -o OUT`` run to the end, which must leave no
    process behind (no resident, no daemon: nothing outlives the command)."""
    import os
    import resource
    import time

    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.monotonic()
    r = subprocess.run([*CLI, "plan", str(path), "-o", str(out)], capture_output=True, text=True, timeout=300,
                       env={**os.environ, "RANGEPLAN_TEST_MARKER": marker})
    wall = time.monotonic() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    assert r.returncode == 0, r.stderr
    assert not _ours(marker)
    return after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime, wall


@pytest.fixture(scope="module")
def slow_request(tmp_path_factory):
    """(file, CPU s at which a command of it is halfway through its plan, wall s of the whole
    command): Table I on the numpy reference at N 40, a plan of CPU seconds, much longer than the
    command's start-up (measured: a compiled Table I command is start-up and a ~0.03 s plan; on
    the reference at the default N 30 the plan is about 0.55 s, too close to this fixture's 0.5 s
    floor: a fresh-clone run measured 0.45 s; at N 40 about 1.8 s)."""
    import os

    from planner.orchestrator.background import kernels_ready

    if not kernels_ready(None):
        pytest.skip("the kernels are not compiled: a plan would start the background compile")
    d = tmp_path_factory.mktemp("slow")
    req = {**json.loads(TABLE1.read_text()), "settings": {"backend": "reference", "N": 40}}
    path = d / "slow.json"
    path.write_text(json.dumps(req))
    start_cpu, _ = _command_cpu(TABLE1, d / "fast.json", f"start-{os.getpid()}")
    cpu, wall = _command_cpu(path, d / "out.json", f"slow-{os.getpid()}")
    assert json.loads((d / "out.json").read_text())["settings"]["backend"] == "reference"
    assert cpu - start_cpu > 0.5, (cpu, start_cpu)  # the plan is CPU seconds: a kill can land inside it
    return path, start_cpu + (cpu - start_cpu) / 2, wall


@pytest.mark.parametrize("sig", ["SIGINT", "SIGKILL"])
def test_a_stopped_command_never_writes_its_output_later(tmp_path, slow_request, sig):
    """The bug of the resident planner: a command stopped mid-plan (Ctrl-C, or killed) whose
    plan then ran to the end elsewhere and overwrote the output of a newer command. Stop one
    halfway through its plan, run a newer command to the same file, wait until well after the
    stopped one would have finished: the file is the newer command's, no process of the
    stopped command is left, and nothing else was written beside it."""
    import os
    import signal
    import time

    path, halfway, wall = slow_request
    out = tmp_path / "out.json"
    marker = f"stop-{sig}-{os.getpid()}"
    t0 = time.monotonic()
    p = subprocess.Popen([*CLI, "plan", str(path), "-o", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True, env={**os.environ, "RANGEPLAN_TEST_MARKER": marker})
    while _cpu_s(p.pid) < halfway:
        assert p.poll() is None, p.communicate()
        time.sleep(0.02)
    p.send_signal(getattr(signal, sig))
    _, err = p.communicate(timeout=60)
    assert p.returncode == (130 if sig == "SIGINT" else -signal.SIGKILL), err
    assert "Traceback" not in err and not out.exists()
    newer = run("plan", str(TABLE1), "--compact", "-o", str(out))
    assert newer.returncode == 0, newer.stderr
    written = out.read_bytes()
    while time.monotonic() < t0 + 2 * wall:  # the stopped plan would have ended by now, and more
        assert not _ours(marker)
        time.sleep(0.1)
    assert out.read_bytes() == written and json.loads(written)["settings"]["backend"] == "compiled"
    assert sorted(f.name for f in tmp_path.iterdir()) == ["out.json"]


def test_no_resident_is_accepted_and_ignored(tmp_path):
    """``--no-resident`` (before issue 34: plan without the resident planner) still parses, so
    scripts that pass it keep working; every plan runs in the command's own process."""
    r = run("plan", str(TABLE1), "--no-resident", "-o", str(tmp_path / "t.csv"))
    assert r.returncode == 0 and (tmp_path / "t.csv").read_text().startswith("time_s,")
    assert "--no-resident" not in run("plan", "--help").stdout


def test_while_the_kernels_compile_plan_and_contour_jobs_move_to_the_reference(monkeypatch, capsys):
    """The CLI applies the service's rule (app.executors.on_reference) when the one decision
    (while_compiling) says the kernels are compiling: a plan and a contour job plan on the numpy
    reference, one note on stderr (with the plan's estimate on the reference); asked for another
    backend, or with the kernels compiled, the job is left as it is."""
    import planner.orchestrator.background as background
    from app.cli import reference_while_compiling
    from app.jobs import ContourJob, PlanJob
    from planner.schema import ContourRequest, PlanRequest

    asked = []

    class Running:
        def note(self, plan_s):
            return f"compiling; plan {plan_s}"

    def while_compiling(backend, mode):
        asked.append((backend, mode))
        return Running() if compiling and backend == "compiled" else None

    monkeypatch.setattr(background, "while_compiling", while_compiling)
    req = json.loads(TABLE1.read_text())
    plan = PlanJob(PlanRequest.model_validate(req))
    contour = ContourJob(ContourRequest.model_validate({"program": "G1 X1 F100\n", "settings": {"Ts": 0.01}}))
    compiling = True
    moved = reference_while_compiling(plan)
    assert isinstance(moved, PlanJob)
    assert moved.request.settings.backend == "reference" and plan.request.settings.backend == "compiled"
    note = capsys.readouterr().err
    assert note.startswith("compiling; plan ") and float(note.split()[-1]) > 0  # its estimate on the reference
    moved_contour = reference_while_compiling(contour)
    assert isinstance(moved_contour, ContourJob)
    assert moved_contour.request.settings == {"Ts": 0.01, "backend": "reference"}
    assert capsys.readouterr().err == "compiling; plan None\n"
    assert asked == [("compiled", plan.request.settings.mode), ("compiled", contour.request.plan_settings().mode)]
    on_ref = PlanJob(PlanRequest.model_validate({**req, "settings": {"backend": "reference"}}))
    assert reference_while_compiling(on_ref) is on_ref
    compiling = False
    assert reference_while_compiling(plan) is plan and reference_while_compiling(contour) is contour
    assert capsys.readouterr().err == ""


CAM = __import__("pathlib").Path(__file__).resolve().parent / "data" / "cam"


def test_plan_and_contour_submit_the_apis_typed_job_to_the_in_process_executor(tmp_path, monkeypatch):
    """``rangeplan plan`` and ``rangeplan contour`` run one typed job each (a PlanJob, a
    ContourJob) on the in-process executor, with no time limit of their own (the command is the
    user's to stop), and write exactly the bytes the job answered (one serializer per format)."""
    from app.cli import run as cli_run
    from app.executors import InProcessExecutor
    from app.jobs import ContourJob, PlanJob

    ran = []
    real = InProcessExecutor.run

    def recording(self, job, timeout_s=None):
        out = real(self, job, timeout_s)
        ran.append((job, out))
        return out

    monkeypatch.setattr(InProcessExecutor, "run", recording)
    for fmt in ("json", "csv"):
        out = tmp_path / f"plan.{fmt}"
        assert cli_run(["plan", str(TABLE1), "--compile", "-o", str(out)]) == 0
        job, done = ran[-1]
        assert isinstance(job, PlanJob) and job.format == fmt and done.ok
        assert job.work_limit_s is None  # no limit: the in-process executor cannot stop a job
        if fmt == "csv":
            assert out.read_bytes() == done.payload
        else:  # indented unless --compact: the same document
            assert json.loads(out.read_bytes()) == json.loads(done.payload)
    part = Path(__file__).resolve().parents[1] / "app" / "static" / "examples" / "contour-part.ngc"
    out = tmp_path / "part.ngc"
    assert cli_run(["contour", str(part), "--origin=-0.013,-0.0075", "--compile", "--progress", "never",
                    "-o", str(out)]) == 0
    job, done = ran[-1]
    assert isinstance(job, ContourJob) and job.format == "gcode" and done.ok and out.read_bytes() == done.payload
    assert len(ran) == 3


def test_contour_progress_on_stderr(tmp_path):
    """``rangeplan contour --progress always``: lines ``contour: k/N passes, ..., ~T s left`` on
    stderr (not a terminal: the first pass's line and the last), k rising to N, N the plan's
    passes; the output file is the same plan as with ``--progress never``, which says nothing."""
    import re

    prog = CAM / "freecad_linuxcnc.ngc"
    outs = {}
    for mode in ("always", "never"):
        out = tmp_path / f"{mode}.json"
        r = run("contour", str(prog), "--origin", "fit", "--progress", mode, "-o", str(out))
        assert r.returncode == 0, r.stderr
        outs[mode] = (json.loads(out.read_text()), r.stderr)
    lines = re.findall(r"contour: (\d+)/(\d+) passes, \d+ s(?:, ~(\d+) s left)?", outs["always"][1])
    passes = outs["always"][0]["contour"]["passes"]
    total = passes if isinstance(passes, int) else len(passes)
    assert lines and {int(n) for _, n, _ in lines} == {total}, outs["always"][1]
    done = [int(k) for k, _, _ in lines]
    assert done == sorted(done) and done[0] == 0 and done[-1] == total
    assert "contour:" not in outs["never"][1]
    a, b = outs["always"][0], outs["never"][0]
    assert np.array_equal(np.array(a["pose"]), np.array(b["pose"]))


def test_progress_line_on_a_terminal_is_one_line_rewritten():
    """On a terminal the line is rewritten in place (carriage return, erase to the end), at
    most 10 times a second, and the last pass always shown; ``auto`` shows nothing before
    2 s; the time left is :func:`app.job_progress.time_left`'s."""
    import io

    from app.cli import PROGRESS_AFTER_S, ProgressLine
    from app.job_progress import time_left

    class Tty(io.StringIO):
        def isatty(self):
            return True

    clock = [100.0]
    for mode, expect_lines in (("always", True), ("auto", False)):
        out = Tty()
        line = ProgressLine(out, mode)
        line._clock = lambda: clock[0]
        line.t0 = clock[0] = 100.0
        line(0, 4, 8.0)
        clock[0] += 0.05
        line(1, 4, 8.0)  # within 0.1 s of the last line: not shown
        clock[0] += 0.5
        line(2, 4, 8.0)
        clock[0] += 0.01
        line(4, 4, 8.0)  # the last: always shown
        line.close()
        text = out.getvalue()
        if expect_lines:
            shown = [s for s in text.split("\r") if s]
            assert [s.split(" passes")[0] for s in shown] == ["contour: 0/4", "contour: 2/4", "contour: 4/4"], text
            left = time_left(2, 4, 100.0, 100.55, 100.55, 8.0)
            assert f"~{left:.0f} s left" in shown[1] and text.endswith("\n")
        else:  # 0.56 s < PROGRESS_AFTER_S: nothing
            assert PROGRESS_AFTER_S > 0.56 and text == ""


def test_contour_z_axis_flags_bound_the_z_of_the_plan(tmp_path):
    """``--z-rapid`` and ``--z-accel`` are the request's ``z_rapid_m_s`` and ``z_accel_m_s2``:
    the plan's Z (``contour.z_m``, differenced at Ts, at rest before and after) keeps within the
    flags' speed and acceleration and reaches most of the acceleration (a bound that holds, not
    crawling); slower flags give a longer plan than the defaults; a value out of range exits 2
    naming the field."""
    prog = tmp_path / "plunge.ngc"
    prog.write_text("G21 G90\nG0 Z2\nG0 X5 Y5\nG1 Z-1 F300\nG1 X15 F600\nG0 Z2\nM2\n")
    out = {}
    for name, flags in (("slow", ["--z-rapid", "0.02", "--z-accel", "0.25"]), ("default", [])):
        path = tmp_path / f"{name}.json"
        r = run("contour", str(prog), "--origin", "fit", "--progress", "never", "-o", str(path), *flags)
        assert r.returncode == 0, r.stderr
        out[name] = json.loads(path.read_text())
    slow = out["slow"]
    ts = slow["settings"]["Ts"]
    z = np.asarray(slow["contour"]["z_m"], dtype=float)
    vz = np.abs(np.diff(z)) / ts
    az = np.abs(np.diff(np.r_[z[0], z, z[-1]], 2)) / ts ** 2
    assert vz.max() <= 0.02 * (1 + 1e-6), vz.max()
    assert 0.3 * 0.25 <= az.max() <= 0.25 * (1 + 1e-6), az.max()
    assert len(slow["time"]) > len(out["default"]["time"])
    r = run("contour", str(prog), "--z-accel", "0", "-o", str(tmp_path / "bad.json"))
    assert r.returncode == 2 and "z_accel_m_s2" in r.stderr, r.stderr
