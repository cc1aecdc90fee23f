"""A pass that goes back over its own path (issue 35, the ``fastest`` ramp regression): a ramp
down a line and back along it at depth, a helix of one turn that ends where it starts, and a
tab on a line, each move with its own F.

Before: ``fastest`` at Ts 10 ms let the robot stay at the ramp's start (the two cells of the line
and its return were one region: no junction held a sample at the far end; the cut missed the
path by 2 mm at a tolerance of 0.05 mm), projected the helix's last samples onto its start (Z
-0.5 asked where -0.8 was), and fell back to a program feed at the speeds the skipped moves
"ran" (0.2 mm/s): ``too_large`` after ~40 CPU s.

Checked here, independently of the planner: the cut within the tolerance both ways of rs274's
path (:func:`tests.test_contour.assert_two_sided`); the tool point (X, Y, Z) of the exported
program within the tolerance of the source's 3-D path; each sample's move, found here by
following the path (:func:`follow`: the nearest point of rs274's path within a sample's travel
of the one before, never the nearest of the whole path, which on a retraced line is the other
way's), non-decreasing and the planner's reported source line wherever the sample is clear of a
move's ends; the program feed never faster than the F of the move it is on, by finite
differences of the samples.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from planner.contour import plan_contour
from planner.exchange.gcode import to_gcode
from tests.test_contour import arc_points, assert_two_sided
from tests.test_gcode_in import canonical_moves
from tests.test_machine_program import PRINTED_MM, _program_frame, _samples, _source_distance

TOL_MM = 0.05
#: (G-code, F mm/min) of each cut move, in order: the ramp A -> B, back B -> A at depth, the
#: helix (its end on its start), a line, the tab's flank up, its top, its flank down, a line
MOVES = [("G1 X5 Z-0.5", 600), ("G1 X1", 300), ("G2 X1 Y5 Z-0.8 I1 J0", 450), ("G1 Y3", 900),
         ("G1 Y2.5 Z-0.5", 500), ("G1 Y2", 700), ("G1 Y1.5 Z-0.8", 400), ("G1 Y0.5", 800)]
PROGRAM = ("G21 G90 G17\nG64 P0.05\nG0 Z2\nG0 X1 Y5\nG1 Z-0.1 F300\n"
           + "".join(f"{g} F{f}\n" for g, f in MOVES) + "G0 Z2\nM2\n")
FIRST_LINE = 6  # the source line of the first cut move
ORIGIN = [0.0, 0.0]


def follow(pose: np.ndarray, path: np.ndarray, owner: np.ndarray, tol: float) -> np.ndarray:
    """Per sample (``pose`` (K, 2)) the move it is on, following the path ``path`` (dense
    points (P, 2) in order, ``owner`` the move of each): from the path's start, each sample's
    nearest path point among those from ``tol`` behind the previous sample's to the previous
    one's plus the sample's own travel and ``2 tol`` ahead (the path's progress never jumps to
    where it passes again later)."""
    s = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(path, axis=0).T))))
    at, out = 0, np.zeros(len(pose), np.int64)
    for k, p in enumerate(pose):
        step = float(np.hypot(*(p - pose[k - 1]))) if k else 0.0
        lo = int(np.searchsorted(s, s[at] - tol))
        hi = int(np.searchsorted(s, s[at] + step + 2 * tol, side="right"))
        at = lo + int(np.argmin(np.hypot(*(path[lo:hi] - p).T)))
        out[k] = owner[at]
    return out


def rs274_moves(origin) -> tuple[np.ndarray, np.ndarray]:
    """rs274's cut moves of :data:`PROGRAM` (feed moves in XY below Z 0) as dense points
    (robot frame [m], at most 1 um apart) and the index of the move (0.. in :data:`MOVES`) of each."""
    moves, _ = canonical_moves(PROGRAM)
    pts: list[np.ndarray] = []
    owner: list[np.ndarray] = []
    prev = np.zeros(3)
    for mv in moves:
        if mv[0] == "dwell":
            continue
        end = np.array([mv[1], mv[2], mv[3] if mv[0] == "line" else mv[6]])
        cuts = min(prev[2], end[2]) < 0 and np.hypot(*(end[:2] - prev[:2])) > 0 or mv[0] == "arc"
        if cuts and not (mv[0] == "line" and mv[4]):
            if mv[0] == "line":
                n = max(int(np.ceil(np.hypot(*(end[:2] - prev[:2])) / 1e-6)), 1)
                seg = prev[:2] + np.linspace(0, 1, n + 1)[:, None] * (end[:2] - prev[:2])
            else:
                seg = arc_points(mv, prev, end, lambda sweep, r: max(int(np.ceil(abs(sweep) * r / 1e-6)), 2))
            pts.append(seg[1:] if pts else seg)
            owner.append(np.full(len(pts[-1]), len(owner)))
        prev = end
    return np.vstack(pts) + np.asarray(origin), np.concatenate(owner)


def _cut(res) -> np.ndarray:
    c = res.contour
    return np.flatnonzero(np.asarray(c.cutting))


@functools.cache
def _plan(feed: str):
    return plan_contour({"program": PROGRAM, "origin": ORIGIN, "feed": feed, "settings": {"Ts": 0.01}})


@pytest.fixture(params=["fastest", "program"])
def planned(request):
    return request.param, _plan(request.param)


def test_the_path_rs274_reads_is_the_one_meant():
    """The test's own reading of the program: 8 moves, the return on the ramp's line, the
    helix's end on its start."""
    path, owner = rs274_moves(ORIGIN)
    assert list(np.unique(owner)) == list(range(len(MOVES)))
    ramp, back = path[owner == 0], path[owner == 1]
    assert np.allclose(ramp[-1], [0.005, 0.005]) and np.allclose(back[-1], [0.001, 0.005])
    helix = path[owner == 2]
    assert np.hypot(*(helix[-1] - back[-1])) < 1e-9 and np.ptp(helix[:, 0]) == pytest.approx(0.002, abs=1e-8)


def test_a_retraced_pass_is_planned_within_the_tolerance_both_ways(planned):
    """Planned at Ts 10 ms (fastest ended ``too_large`` before), the cut within G64 P of the
    path and the path, the far end of the retraced line included, within G64 P of the cut."""
    feed, res = planned
    assert res.settings.Ts == pytest.approx(0.01)
    (cut_d, path_d), = assert_two_sided(res, PROGRAM, ORIGIN)
    assert path_d <= TOL_MM * 1e-3
    far_end = np.array([0.005, 0.005]) + ORIGIN
    assert float(np.hypot(*(res.pose[_cut(res), :2] - far_end).T).min()) <= TOL_MM * 1e-3


def test_each_sample_is_on_the_move_the_path_has_reached(planned):
    """Each cut sample's move, found by following the path, never goes back; the planner's
    source line is that move wherever the sample is farther than the tolerance from the move's
    ends (near an end either neighbour may hold it); and the tool point (X, Y, Z) of the
    exported program within the tolerance of the source's 3-D path (a sample on the return
    given the ramp's Z, or the helix's end its start's, would be 0.3-0.4 mm off)."""
    feed, res = planned
    tol = TOL_MM * 1e-3
    path, owner = rs274_moves(ORIGIN)
    k = _cut(res)
    pose = res.pose[k, :2]
    move = follow(pose, path, owner, tol)
    assert np.all(np.diff(move) >= 0) and move[0] == 0 and move[-1] == len(MOVES) - 1
    assert set(move) == set(range(len(MOVES)))  # every move has samples, the retraced one too
    line = np.array([res.contour.program_line[i] for i in k]) - FIRST_LINE
    assert np.all(np.diff(line) >= 0)
    ends = np.array([path[owner == j][[0, -1]] for j in range(len(MOVES))])  # (moves, 2, 2)
    clear = np.hypot(*(pose[:, None, None, :] - ends[move]).transpose(3, 0, 1, 2)).min(axis=(1, 2)) > tol
    assert clear.sum() >= len(k) // 2
    assert np.array_equal(line[clear], move[clear]), np.flatnonzero(line[clear] != move[clear])
    ts = float(res.settings.Ts)
    xyz, _ = _samples(to_gcode(res, source="z"), ts)
    first, last = k[[0, -1]]
    dist = _source_distance(PROGRAM, _program_frame(xyz[first:last + 1], res.contour.origin))
    assert dist.max() <= tol + 2 * PRINTED_MM * 1e-3, dist.max()


def test_program_feed_never_faster_than_the_move_s_f_on_a_retraced_path():
    """``program`` feed: each straight move between two cut samples (its length over its time,
    as the exported program runs it) no faster than the F of the moves its two ends are on,
    found by following the path (the return runs at half the ramp's F along the same line), nor
    any sample's speed; and the time is not a crawl: the return and the ramp each reach 0.9 F
    somewhere."""
    res = _plan("program")
    tol = TOL_MM * 1e-3
    path, owner = rs274_moves(ORIGIN)
    k = _cut(res)
    move = follow(res.pose[k, :2], path, owner, tol)
    f = np.array([m[1] for m in MOVES]) * 1e-3 / 60
    chord = np.hypot(*np.diff(res.pose[k, :2], axis=0).T) / np.diff(res.time[k])
    allowed = np.minimum(f[move[:-1]], f[move[1:]])
    assert np.all(chord <= allowed * (1 + 1e-6)), float((chord / allowed).max())
    speed = np.hypot(*res.velocity[k, :2].T)
    assert np.all(speed <= f[move] * (1 + 1e-6)), float((speed / f[move]).max())
    for j in (0, 1):
        assert chord[(move[:-1] == j) & (move[1:] == j)].max() >= 0.9 * f[j]


def _line(a, b, z0=0.0, z1=0.0):
    from planner.schema import PathElement

    a, b = np.asarray(a, float), np.asarray(b, float)
    return PathElement(kind="line", line=1, start=a.tolist(), end=b.tolist(), length_m=float(np.hypot(*(b - a))),
                       z_start_m=z0, z_end_m=z1, feed_m_s=0.01)


def test_a_helix_s_last_samples_get_its_end_s_z_and_first_its_start_s():
    """A full circle (its end its start) going down 0.3 mm: samples all the way round, the
    first a hair behind the start, the last on it: Z from the first to the last follows the
    angle travelled (the start's Z at the start, the end's at the end, never the start's
    again), and each sample's XY distance from its point is its distance from the circle (the
    first's from the start). Before, the last sample was given the start's Z (0.3 mm off)."""
    from planner.contour.zaxis import programmed_z
    from planner.exchange import read_gcode

    prog = read_gcode("G21 G90 G17\nG0 X1 Y5\nG1 Z-0.5 F300\nG2 X1 Y5 Z-0.8 I1 J0 F450\nG0 Z2\nM2\n")
    els = prog.passes[0].elements
    (e,) = els
    assert e.centre is not None and e.radius_m is not None
    c, r = np.asarray(e.centre), float(e.radius_m)
    a = math.pi - np.linspace(-1e-4, 2 * math.pi, 60)  # clockwise from (1, 5), the first 1e-4 rad before it
    off = np.resize([0.0, 2e-6, -2e-6], len(a))
    pose = c + (r + off)[:, None] * np.column_stack((np.cos(a), np.sin(a)))
    z, d = programmed_z(pose, np.zeros(len(a), np.int64), els, np.zeros(2))
    travelled = np.clip((math.pi - a) / (2 * math.pi), 0.0, 1.0)
    assert z == pytest.approx(-0.5e-3 - 0.3e-3 * travelled, abs=1e-12)
    assert z[-1] == pytest.approx(-0.8e-3) and z[0] == pytest.approx(-0.5e-3)
    assert d[1:] == pytest.approx(np.abs(off[1:]), abs=1e-12)
    assert d[0] == pytest.approx(float(np.hypot(*(pose[0] - np.asarray(e.start)))), abs=1e-12)  # behind: the start


def test_a_move_passed_between_two_samples_has_the_speed_the_path_ran_at():
    """Three moves (1 mm, 0.01 mm, 1 mm) run at 20 mm/s sampled every 10 ms: no sample on the
    short one; its speed (and each move's) from the samples' progress is the speed run, never 0
    (as an F, 0 takes a hundred thousand samples); a move retraced (back along the first) is
    told apart from the first by the progress, not by where its samples are."""
    from planner.contour.path import move_speeds, progress

    els = [_line([0, 0], [1e-3, 0]), _line([1e-3, 0], [1.01e-3, 0]), _line([1.01e-3, 0], [0.01e-3, 0])]
    v, Ts = 0.02, 0.01
    s = 0.1e-3 + v * Ts * np.arange(10)  # path length of each sample: 0.1, 0.3, ..., 1.9 mm
    ends = np.cumsum([e.length_m for e in els])
    elem = np.minimum(np.searchsorted(ends, s, side="right"), 2)
    assert 1 not in elem  # the short move has no sample
    pose = np.array([els[k].point_at(np.array([x - (ends[k] - els[k].length_m)]))[0] for k, x in zip(elem, s)])
    got = progress(pose, elem, els, np.zeros(2))
    assert got.s == pytest.approx(s, abs=1e-12) and np.all(np.diff(got.s) >= 0)
    speeds = move_speeds(Ts * np.arange(len(s)), np.full(len(s), v), elem, got.s, [0, 1, 2], els)
    assert speeds == pytest.approx([v, v, v], rel=1e-9)
    slow = np.where(elem == 2, v / 2, v)  # the return run at half the speed: its own, not the first's
    s2 = np.concatenate(([0.0], np.cumsum(slow[:-1] * Ts)))
    elem2 = np.minimum(np.searchsorted(ends, s2, side="right"), 2)
    pose2 = np.array([els[k].point_at(np.array([x - (ends[k] - els[k].length_m)]))[0] for k, x in zip(elem2, s2)])
    sp = move_speeds(Ts * np.arange(len(s2)), np.where(elem2 == 2, v / 2, v), elem2,
                     progress(pose2, elem2, els, np.zeros(2)).s, [0, 2], els)
    assert sp[0] == pytest.approx(v) and sp[1] <= v / 2 * (1 + 1e-9)
