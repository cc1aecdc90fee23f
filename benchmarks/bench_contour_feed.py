"""The ``program`` feed against the exact path's third-order optimum capped at F (issue 35
goal 2: cutting time <= 1.02x it on every pass, no sample faster than F): per pass, one or
more checkouts side by side, and where the time goes.

    OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python benchmarks/bench_contour_feed.py \
        [--root /tmp/base --root .] [--programs bench,freecad_linuxcnc.ngc,fusion360.nc] [--elements] [--profile] \
        [--lag] [--feed fastest]

``--feed fastest``: the ``fastest`` feed instead, against the same third-order optimum without
the F cap (``bench_contour_optimum``'s fair peer, cached the same way): its before/after per pass
in one run.

The peer is ``bench_contour_optimum``'s (``third_order_optimum`` with ``feed_cap``: the same
robot, drive forces, leg speeds, the default force-rate limit and the Z axis speed; grids 24,
48, 96 steps per element, doubled until two agree within 0.1 %), solved once per distinct pass
and kept in ``--cache`` (by the pass's geometry, feeds and origin; ``--no-cache`` solves again).

Each ``--root`` is planned in a fresh process with ``PYTHONPATH`` on it (``feed`` ``program``
at the defaults, after one untimed plan that loads the kernels): per pass ``time_s`` and the
largest tool speed over F while cutting, and the CPU seconds of the whole plan. The table gives
each root's time over the peer's per pass.

``--profile`` (the last root, in this process): per distinct pass, its first 10 and last 8
samples' travel over ``F Ts`` against the peer's mean speed over F in the same samples, and the
samples each loses there and between them against L / F.

``--lag`` (the last root, in this process): per distinct pass, the plan's lag behind the peer
at the same path position (``j Ts - t_peer(s_j)``, in samples) gained in each phase: the first
sample, the speeding up, the cruise, the braking, the stop (:func:`lag_rows`); its end is the
pass's time over the peer's.

``--elements`` (the last root, in this process): per distinct pass and per program line, the
peer's time and top speed beside the plan's (the samples cutting that line: their count times
Ts, and their top speed from finite differences of the tool point), and the pass's samples
before its first move starts and after it reaches its end within the tolerance (the start and
the settle).
"""

from __future__ import annotations

import argparse
import hashlib
import importlib
import json
import math
import os
import pickle
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
HERE = Path(__file__).resolve().parent

import numpy as np  # noqa: E402

GRIDS = [24, 48, 96]


def _paths(root: str | None = None) -> None:
    if root is not None:
        sys.path.insert(0, str(Path(root).resolve()))
    sys.path.insert(1 if root is not None else 0, str(HERE))


def one(name: str, feed: str = "program") -> None:
    """Plan the program ``name`` in ``feed`` in this process; print JSON per pass."""
    from planner.contour import plan_contour

    _paths()
    import bench_contour  # type: ignore[import-not-found]
    from bench_contour_optimum import load_program  # type: ignore[import-not-found]

    plan_contour({"program": bench_contour.program(1), "origin": bench_contour.ORIGIN})  # the kernels loaded
    _, text, origin = load_program(name)
    c0 = time.process_time()
    res = plan_contour({"program": text, "origin": origin, "feed": feed})
    cpu = time.process_time() - c0
    c = res.contour
    assert c is not None
    where = str(Path(sys.modules["planner"].__file__ or "").parent.parent)
    print(json.dumps({"planner": where, "cpu": cpu, "times": [p.time_s for p in c.passes],
                      "ratio": [p.max_feed_ratio for p in c.passes], "Ts": res.settings.Ts,
                      "origin": list(c.origin), "tol": c.tolerance_m}))


def run_root(root: str, name: str, feed: str = "program") -> dict:
    env = dict(os.environ, PYTHONPATH=str(Path(root).resolve()), OPENBLAS_NUM_THREADS="1")
    out = subprocess.run([sys.executable, __file__, "--one", name, "--feed", feed], env=env, capture_output=True,
                         text=True)
    if out.returncode != 0:
        raise SystemExit(f"{root}: {out.stderr[-2000:]}")
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert Path(got["planner"]) == Path(root).resolve(), (got["planner"], root)
    return got


def pass_key(els, origin, z_acc: float) -> str:
    """The cache key of a pass's peer: its moves, feeds, Z, origin and grids, and the Z axis
    acceleration where the pass moves Z (elsewhere it bounds nothing: the same optimum)."""
    key: tuple = (tuple((e.kind, *np.round(e.start, 9), *np.round(e.end, 9), round(e.sweep_rad or 0.0, 9),
                         round(e.feed_m_s, 9), round(e.z_start_m, 9), round(e.z_end_m, 9)) for e in els),
                  tuple(np.round(origin, 9)), GRIDS)
    if any(e.z_end_m != e.z_start_m and e.length_m > 1e-12 for e in els):
        key += (("z_acc", z_acc),)
    return hashlib.sha256(repr(key).encode()).hexdigest()[:20]


def capped_peer(robot, els, origin, rate, cache: Path | None, capped: bool = True) -> dict:
    """The F-capped third-order optimum of one pass, converged (as ``converged_optimum``), with
    its per-element times, top speeds and speed profiles; cached by the pass. The Z axis's speed
    and acceleration as the planner holds them (``bench_contour_optimum``'s fair peer; before
    2026-11-28 10:00 this peer held the Z speed alone: fusion360's ramps). ``capped`` False: the
    same optimum without F (``fastest``'s peer, ``--feed fastest``)."""
    from bench_contour_optimum import Z_ACC_M_S2, Z_MAX_M_S, third_order_optimum  # type: ignore[import-not-found]

    key = pass_key(els, origin, Z_ACC_M_S2) + ("" if capped else "-uncapped")
    path = cache / f"{key}.pkl" if cache is not None else None
    if path is not None and path.exists():
        return pickle.loads(path.read_bytes())
    grids, runs, guess = list(GRIDS), [], None
    k = 0
    while k < len(grids):
        opt, guess = third_order_optimum(robot, els, origin, grids[k], rate, capped, False, z_max=Z_MAX_M_S,
                                         z_acc=Z_ACC_M_S2, guess=guess)
        runs.append(opt)
        k += 1
        if k == len(grids) and abs(runs[-1].time_s / runs[-2].time_s - 1) > 1e-3 and 2 * grids[-1] <= 192:
            grids.append(2 * grids[-1])
    last = runs[-1]
    assert guess is not None
    got = {"time": last.time_s, "status": [r.status for r in runs], "times": [r.time_s for r in runs],
           "el_time": last.element_time_s, "el_speed": last.element_speed_m_s,
           "lines": [e.line for e in els if e.length_m > 1e-12], "t": guess["t"], "v": guess["v"]}
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(pickle.dumps(got))
    return got


def cutting_run(res, k: int, where: str, what: str) -> tuple[int, int] | list[str]:
    """The samples [a, b) of the plan's ``k``-th cutting run, or the note ``where`` prints in
    place of its ``what`` if the runs are not one a pass."""
    c = res.contour
    edges = np.flatnonzero(np.diff(np.concatenate(([0], np.asarray(c.cutting, int), [0]))))
    if len(edges) != 2 * len(c.passes):
        return [f"\n{where}: {len(edges) // 2} cutting runs for {len(c.passes)} passes, no {what}"]
    return int(edges[2 * k]), int(edges[2 * k + 1])


def element_rows(label: str, i: int, els, peer: dict, res, k: int, tol: float) -> list[str]:
    """Where pass ``i`` (the ``k``-th cutting run) loses its time against the peer (``--elements``)."""
    run = cutting_run(res, k, f"{label} pass {i}", "table")
    if isinstance(run, list):
        return run
    (a, b), c, Ts = run, res.contour, res.settings.Ts
    lines = np.array([-1 if x is None else x for x in c.program_line[a:b]])
    xy = res.pose[a:b, :2]
    step = np.hypot(*np.diff(xy, axis=0).T) / Ts
    origin = np.asarray(c.origin, float)
    start = np.asarray(els[0].start, float) + origin
    end = np.asarray(els[-1].end, float) + origin
    moved = np.flatnonzero(np.hypot(*(xy - start).T) > tol)
    away = np.flatnonzero(np.hypot(*(xy - end).T) > 1e-6)  # a closed pass starts at its end: the last time away
    head = int(moved[0]) if len(moved) else 0
    tail = max((b - a) - int(away[-1]) - 2, 0) if len(away) else 0  # the samples after the arrival's
    out = [f"\n{label} pass {i}: {b - a} samples of {Ts * 1e3:g} ms = {(b - a) * Ts:.3f} s against the peer's "
           f"{peer['time']:.4f} s; {head} samples before the tool leaves its start by the tolerance, {tail} after it "
           "is within 1 um of the end\n",
           "| line | kind | mm | F mm/min | peer s | peer top mm/min | plan s | plan top mm/min | plan - peer s |",
           "|---|---|---|---|---|---|---|---|---|"]
    els = [e for e in els if e.length_m > 1e-12]
    seen: list[int] = []
    for e in els:
        if e.line in seen:
            continue
        seen.append(e.line)
        js = [j for j, x in enumerate(els) if x.line == e.line]
        m = lines == e.line
        top = float(step[m[:-1]].max()) if m[:-1].any() else 0.0
        pt = float(sum(peer["el_time"][j] for j in js))
        ps = float(max(peer["el_speed"][j] for j in js))
        L = sum(els[j].length_m for j in js)
        out.append(f"| {e.line} | {'+'.join(els[j].kind for j in js)} | {L * 1e3:.2f} | {e.feed_m_s * 6e4:.0f} | "
                   f"{pt:.4f} | {ps * 6e4:.1f} | {m.sum() * Ts:.3f} | {top * 6e4:.1f} | {m.sum() * Ts - pt:+.3f} |")
    return out


def profile_rows(label: str, i: int, els, peer: dict, res, k: int, head: int = 10, tail: int = 8) -> list[str]:
    """The start and the end of pass ``i`` (the ``k``-th cutting run) sample by sample against the
    peer's profile at the same times (``--profile``): each sample's travel over ``F Ts`` and the
    peer's speed over F, and the samples each loses there against L / F (``sum(1 - v / F)``)."""
    run = cutting_run(res, k, f"{label} pass {i}", "profile")
    if isinstance(run, list):
        return run
    (a, b), Ts = run, res.settings.Ts
    F = max(e.feed_m_s for e in els)
    step = np.hypot(*np.diff(res.pose[a:b, :2], axis=0).T) / (F * Ts)
    # the peer's profile per element (its own clock from 0): one clock over the pass
    t_el = [np.asarray(x, float) for x in peer["t"]]
    start = np.concatenate(([0.0], np.cumsum([x[-1] for x in t_el])))[:-1]
    t_peer = np.concatenate([x + t0 for x, t0 in zip(t_el, start)])
    v_peer = np.concatenate([np.asarray(x, float).ravel()[:len(tx)] for x, tx in zip(peer["v"], t_el)])
    n_peer = int(math.ceil(t_peer[-1] / Ts - 1e-9))
    mid = (np.arange(n_peer) + 0.5) * Ts  # the peer's mean speed over each sample, at its middle
    peer_step = np.interp(mid, t_peer, v_peer) / F
    out = [f"\n{label} pass {i}: each sample's travel over F Ts, the plan against the peer at the same time "
           f"(plan {len(step)} samples, peer {t_peer[-1] / Ts:.1f})\n",
           "| where | plan | peer | plan lost, samples | peer lost, samples |", "|---|---|---|---|---|"]
    for name, pl, pe in (("start", step[:head], peer_step[:head]), ("end", step[-tail:], peer_step[-tail:])):
        out.append(f"| {name} | {' '.join(f'{x:.2f}' for x in pl)} | {' '.join(f'{x:.2f}' for x in pe)} | "
                   f"{float(np.sum(1 - pl)):.2f} | {float(np.sum(1 - pe)):.2f} |")
    body, pbody = step[head:-tail], peer_step[head:-tail]
    out.append(f"| between | {body.min():.2f}-{body.max():.2f} | {pbody.min():.2f}-{pbody.max():.2f} | "
               f"{float(np.sum(1 - body)):.2f} | {float(np.sum(1 - pbody)):.2f} |")
    return out


def lag_rows(label: str, i: int, els, peer: dict, res, k: int) -> list[str]:
    """Where pass ``i`` (the ``k``-th cutting run) falls behind the peer (``--lag``): per sample
    ``j`` of the plan (from the pass's start, at rest: the sample before the run), its lag
    ``j Ts - t_peer(s_j)`` in samples, ``s_j`` its path length (the travel of its samples, scaled
    to the pass's length: chords of arcs), ``t_peer`` when the peer is there; by phase: the
    first sample, the speeding up (to the first sample within 5 % of the pass's top speed), the
    cruise, the braking (from the last sample within 5 % of the top to where the plan's speed is
    under 20 % of it), the stop. The lag at the end is the pass's time over the peer's."""
    run = cutting_run(res, k, f"{label} pass {i}", "lag")
    if isinstance(run, list):
        return run
    (a, b), Ts = run, res.settings.Ts
    t_el = [np.asarray(x, float) for x in peer["t"]]
    t0 = np.concatenate(([0.0], np.cumsum([x[-1] for x in t_el])))[:-1]
    tp = np.concatenate([x + t for x, t in zip(t_el, t0)])
    vp = np.concatenate([np.asarray(x, float).ravel()[:len(tx)] for x, tx in zip(peer["v"], t_el)])
    order = np.argsort(tp, kind="stable")
    tp, vp = tp[order], vp[order]
    sp = np.concatenate(([0.0], np.cumsum(0.5 * (vp[1:] + vp[:-1]) * np.diff(tp))))
    xy = res.pose[a - 1:b, :2]  # from the pass's start (the sample before its run) to its last
    s = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))))
    s = s * sum(e.length_m for e in els) / max(float(s[-1]), 1e-300)
    lag = (np.arange(len(s)) * Ts - np.interp(s, sp * s[-1] / sp[-1], tp)) / Ts
    v = np.hypot(*np.diff(xy, axis=0).T) / Ts
    top = float(v.max())
    up = int(np.flatnonzero(v >= 0.95 * top)[0]) + 1
    down = int(np.flatnonzero(v >= 0.95 * top)[-1]) + 1
    slow = [j + 1 for j in range(down, len(v)) if v[j] < 0.2 * top]
    stop = slow[0] if slow else len(v)
    marks = [("first sample", 0, 1), ("speeding up", 1, up), ("cruise", up, down), ("braking", down, stop),
             ("stop", stop, len(s) - 1)]
    cells = " | ".join(f"{j0}-{j1}: {lag[j1] - lag[j0]:+.2f}" for _, j0, j1 in marks)
    return [f"| {label} | {i} | {len(s) - 1} | {peer['time'] / Ts:.2f} | {cells} | {lag[-1]:+.2f} |"]


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("--one", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--root", action="append", default=None, help="a checkout to plan with (repeatable; default .)")
    ap.add_argument("--programs", default="bench,freecad_linuxcnc.ngc,fusion360.nc")
    ap.add_argument("--elements", action="store_true", help="per line of each distinct pass: the plan against the peer")
    ap.add_argument("--profile", action="store_true",
                    help="per distinct pass: its first and last samples' speeds against the peer's at the same times")
    ap.add_argument("--lag", action="store_true",
                    help="per distinct pass: the plan's lag behind the peer at the same path position, by phase")
    ap.add_argument("--cache", default=str(Path.home() / ".cache" / "rangeplan" / "bench_contour_feed"))
    ap.add_argument("--no-cache", action="store_true")
    ap.add_argument("--feed", default="program", choices=("program", "fastest"),
                    help="the feed planned; fastest: against the same optimum without F")
    args = ap.parse_args()
    if args.one is not None:
        one(args.one, args.feed)
        return
    roots = args.root or [str(HERE.parent)]
    _paths(roots[-1])
    # the last root's planner for --lag, --profile, --elements (bench_contour_optimum puts its own
    # checkout first on the path: imported first, this script's checkout planned them whatever the roots)
    importlib.import_module("planner")
    from bench_contour_optimum import ROBOT, load_program  # type: ignore[import-not-found]

    from planner.exchange import read_gcode
    from planner.model import load_robot
    from planner.schema.limits import DEFAULT_FORCE_RISE_S

    robot = load_robot(ROBOT)
    rate = np.asarray(robot.force_max, float) / DEFAULT_FORCE_RISE_S
    cache = None if args.no_cache else Path(args.cache)
    print(f"load: {os.getloadavg()[0]:.1f} (1-min average) on {os.cpu_count()} cores; roots: {', '.join(roots)}\n")
    head = " | ".join(f"{Path(r).resolve().name} s | / peer" for r in roots)
    summary: list[str] = []
    peer_col = "3rd order at F s" if args.feed == "program" else "3rd order s"
    rows: list[str] = [f"| program | pass | mm | F mm/min | L / F s | {peer_col} | " + head + " |",
                       "|---|---|---|---|---|---|" + "---|---|" * len(roots)]
    detail: list[str] = []
    lags: list[str] = []
    for name in args.programs.split(","):
        label, text, origin = load_program(name)
        got = [run_root(r, name, args.feed) for r in roots]
        prog = read_gcode(text)
        org, tol = np.asarray(got[-1]["origin"], float), float(got[-1]["tol"])
        res = None
        if args.elements or args.profile or args.lag:
            from planner.contour import plan_contour

            res = plan_contour({"program": text, "origin": origin, "feed": args.feed})
        tot_peer = 0.0
        tot = np.zeros(len(roots))
        done: set[str] = set()
        prev = None
        for i, b in enumerate(prog.passes):
            els = b.elements
            peer = capped_peer(robot, els, org, rate, cache, args.feed == "program")
            tot_peer += peer["time"]
            times = np.array([g["times"][i] for g in got])
            tot += times
            L = sum(e.length_m for e in els)
            nominal = sum(e.length_m / e.feed_m_s for e in els)
            feeds = ", ".join(map(str, sorted({round(e.feed_m_s * 6e4) for e in els})))
            cols = " | ".join(f"{t:.3f} | {t / peer['time']:.3f}x" for t in times)
            row = f"| {L * 1e3:.1f} | {feeds} | {nominal:.3f} | {peer['time']:.4f} | {cols} |"
            if prev is not None and prev[1] == row:
                rows[-1] = f"| {label} | {prev[0]}-{i} {row}"
            else:
                rows.append(f"| {label} | {i} {row}")
                prev = (i, row)
            key = repr([(e.kind, *np.round(e.start, 9), *np.round(e.end, 9), round(e.sweep_rad or 0.0, 9),
                         round(e.feed_m_s, 9), round(e.z_end_m - e.z_start_m, 9)) for e in els])  # depth passes alike
            if res is not None and key not in done:
                done.add(key)
                if args.elements:
                    detail += element_rows(label, i, els, peer, res, i, tol)
                if args.profile:
                    detail += profile_rows(label, i, els, peer, res, i)
                if args.lag:
                    lags += lag_rows(label, i, els, peer, res, i)
        cols = " | ".join(f"{t:.3f} | {t / tot_peer:.3f}x" for t in tot)
        rows.append(f"| {label} | all | | | | {tot_peer:.4f} | {cols} |")
        summary.append(f"| {label} | " + " | ".join(
            f"{g['cpu']:.1f} | {max(r for r in g['ratio'] if r is not None):.4f} | {g['Ts'] * 1e3:g}" for g in got)
            + " |")
    print(f"### {args.feed} feed per pass against the third-order optimum"
          f"{' capped at F' if args.feed == 'program' else ' (no F)'}\n")
    print("\n".join(rows))
    print("\n### compute (CPU s of the whole plan), largest tool speed over F while cutting, Ts ms\n")
    print("| program | " + " | ".join(f"{Path(r).resolve().name} CPU s | max speed / F | Ts" for r in roots) + " |")
    print("|---|" + "---|---|---|" * len(roots))
    print("\n".join(summary))
    if detail:
        print("\n".join(detail))
    if lags:
        print("\n### the plan's lag behind the peer at the same path position, samples (j Ts - t_peer(s_j)), "
              "gained per phase (samples j0-j1 of the plan)\n")
        print("| program | pass | plan samples | peer samples | first sample | speeding up | cruise | braking | stop | "
              "lag at the end |")
        print("|---|---|---|---|---|---|---|---|---|---|")
        print("\n".join(lags))


if __name__ == "__main__":
    main()
