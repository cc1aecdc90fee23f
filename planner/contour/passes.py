"""A contour request's program read into passes and each pass's pieces into tube corridors
(issue 22; :mod:`planner.contour.plan` walks them).

- :func:`parse_contour_request`, :func:`read_program`, :func:`tolerance_of`: the request, its
  G-code program read into blocks (travels, cut passes, dwells), and the tolerance it plans to;
- :func:`chunks`: a pass's elements in pieces the robot plans rest to rest (split at G61 exact
  stops); :func:`travel_run_end`: consecutive travel blocks as one move; :func:`walk_program`:
  the program's free moves and cut passes in the order the planner moves through them;
- :class:`TubeSizes`, :func:`piece_tube`: a piece's tube corridor (:func:`planner.contour.tube.tube`)
  with cells sized for a speed, starting where the robot is, its reach checked;
- :func:`segment_of`, :func:`counts_of`: which tube cell each sample of a plan is in;
- :func:`measure_deviation`: how far each sample, and the straight move to the next, is from
  the programmed path.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Iterator, Sequence
from typing import Any, Literal, NamedTuple

import numpy as np

from ..errors import PlannerError
from ..exchange import read_gcode
from ..model import RobotModel
from ..model.reach import check_segments
from ..schema import (
    DEFAULT_CONTOUR_TOLERANCE_M,
    MAX_SEGMENTS,
    ContourRequest,
    PathElement,
    PlanResult,
    Program,
    ProgramBlock,
    Segment,
    Settings,
    planner_error,
)
from .tube import PathGeometry, Tube, tube

#: fastest: the reference cell speed and acceleration the scale multiplies [m/s, m/s^2]
V0_M_S = 0.1
#: program feed: the profile's cell speed starts at this fraction of F (the robot, pulled to the
#: cells' centres, runs a little faster than the profile between them)
PROGRAM_MARGIN = 0.9
#: the longest cell along the path, in samples at the cell speed (short cells keep the
#: criterion's pull on the cell centre near the path's progress)
CELL_SAMPLES = 4
#: the deviation's candidate elements: those within this many tolerances along the pass of the
#: sample's own (and its neighbours), at most NEAR_MAX of them
NEAR_TOLERANCES = 2.0
NEAR_MAX = 32
#: the cut-to-path deviation's refinement (:func:`measure_deviation`): rounds, each on points 8 times
#: closer along the moves whose bound exceeds the largest distance measured, while a round
#: measures at most CHORD_POINTS_MAX points
CHORD_ROUNDS = 2
CHORD_POINTS_MAX = 200_000
#: the first cells of a pass contain a disk of this radius about where the robot starts [m]
#: (twice the corridor margin: the robot is inside with room to spare)
START_ROOM_M = 2e-6
_RING = np.linspace(0.0, 2 * np.pi, 8, endpoint=False)
#: room for the box about a rapid [m]
RAPID_MARGIN_M = 0.002


def parse_contour_request(request: Any) -> ContourRequest:
    """Validate a contour request (dict or model); errors name the field."""
    if isinstance(request, ContourRequest):
        return request
    from pydantic import ValidationError

    try:
        return ContourRequest.model_validate(request)
    except ValidationError as exc:
        raise planner_error(exc) from None


def read_program(req: ContourRequest, program: Program | None = None) -> Program:
    """The request's G-code program read (:func:`planner.exchange.read_gcode`), or ``program``
    if the caller has read it already."""
    if program is not None:
        return program
    return read_gcode(req.program, cut_below=req.cut_below_m, z_rapid_m_s=req.z_rapid_m_s)


def tolerance_of(req: ContourRequest, program: Program) -> float:
    """The tolerance the program is planned to [m]: the request's ``tolerance_m``, else the
    program's G64 P, else :data:`~planner.schema.DEFAULT_CONTOUR_TOLERANCE_M`."""
    return req.tolerance_m if req.tolerance_m is not None else (program.tolerance_m or DEFAULT_CONTOUR_TOLERANCE_M)


def travel_run_end(blocks: Sequence[Any], i: int) -> int:
    """The index of the last travel block of the run that starts at ``blocks[i]``: consecutive
    travels are one move, from where the first starts to where the last ends."""
    j = i
    while j + 1 < len(blocks) and blocks[j + 1].kind == "travel":
        j += 1
    return j


class WalkStep(NamedTuple):
    """One step of :func:`walk_program`, in the program frame [m]: a ``travel`` (a run of
    travel blocks as one free move, from where the tool is to where the last ends; of length
    0 where it is there already), an ``approach`` (the free move to a cut pass that starts more
    than half the tolerance away from the tool) or a ``cut`` pass (``block``, from its first
    move's start to its last move's end); ``line``: the source line of its first block."""

    kind: Literal["travel", "approach", "cut"]
    line: int
    start: np.ndarray
    end: np.ndarray
    block: ProgramBlock | None = None


def walk_program(program: Program, tol: float) -> Iterator[WalkStep]:
    """The program's free moves and cut passes in the order
    :func:`~planner.contour.plan.plan_contour` moves through them, from where the program
    starts (dwells leave the tool where it is): what the work estimate counts
    (:mod:`planner.contour.estimate`) and the placement checks for reach
    (:mod:`planner.contour.placement`), one walk for both."""
    pos = np.asarray(program.start, float)
    blocks = program.blocks
    i = 0
    while i < len(blocks):
        b = blocks[i]
        if b.kind == "travel":
            j = travel_run_end(blocks, i)
            end = np.asarray(blocks[j].elements[-1].end, float)
            yield WalkStep("travel", b.line, pos, end)
            pos, i = end, j + 1
            continue
        if b.kind == "cut" and b.elements:
            start = np.asarray(b.elements[0].start, float)
            if math.hypot(*(start - pos)) > 0.5 * tol:
                yield WalkStep("approach", b.line, pos, start)
            pos = np.asarray(b.elements[-1].end, float)
            yield WalkStep("cut", b.line, start, pos, b)
        i += 1


def chunks(elements: list[PathElement], split_after: Collection[int] = ()) -> list[list[int]]:
    """The element indices of a pass in pieces the robot plans rest to rest: split after each
    exact-stop move (G61) and after the moves ``split_after`` (``fastest``: where Z's slope
    changes too sharply to pass, :func:`planner.contour.zaxis.slope_stops`)."""
    out: list[list[int]] = [[]]
    for k, e in enumerate(elements):
        out[-1].append(k)
        if k < len(elements) - 1 and (e.exact_stop or k in split_after):
            out.append([])
    return out


class TubeSizes:
    """The tube of a piece with cells sized for a speed [m/s] (:data:`CELL_SAMPLES` samples at
    it, at least 4 tolerances long), each size built once: ``TubeSizes(...)(v)`` is the tube
    for the profile speed ``v`` (:func:`piece_tube`; sizes within 13 % share a tube)."""

    def __init__(self, model: RobotModel, st: Settings, chunk: list[int], els: list[PathElement],
                 origin: np.ndarray, tol: float, psi: float, pos: np.ndarray, elements: list[PathElement]) -> None:
        self.model, self.st, self.chunk, self.els, self.origin = model, st, chunk, els, origin
        self.tol, self.psi, self.pos, self.elements = tol, psi, pos, elements
        self.made: dict[float, Tube] = {}
        self.feed_tubes: dict[bytes, Tube] = {}

    def __call__(self, v: float) -> Tube:
        """The tube whose cells hold :data:`CELL_SAMPLES` samples at the speed ``v`` [m/s]."""
        piece_max = max(v * self.st.Ts * CELL_SAMPLES, 4 * self.tol)
        key = round(math.log(piece_max) * 8)  # sizes within 13 % share a tube
        if key not in self.made:
            self.made[key] = piece_tube(self.model, self.chunk, self.els, self.origin, self.tol, self.psi, self.pos,
                                        self.elements, piece_max)
        return self.made[key]

    def at_feed(self, margin: np.ndarray) -> Tube:
        """``program`` feed's tube: on each move cells of a whole number of samples' travel at
        its F (one sample, or the fewest whose travel is at least 4 tolerances), shortened by
        the move's fraction ``margin`` (per element of the piece): a timing of one sample per
        cell cruising at F then runs the moves between samples at about F / (1 + margin) (the
        criterion holds each sample near its cell's centre, the next one a cell further)."""
        margin = np.round(np.asarray(margin, float), 6)
        key = margin.tobytes()
        if key not in self.feed_tubes:
            step = np.array([e.feed_m_s for e in self.els]) * self.st.Ts
            piece_max = step * np.ceil(4 * self.tol / step - 1e-9).clip(1.0) / (1 + margin)
            self.feed_tubes[key] = piece_tube(self.model, self.chunk, self.els, self.origin, self.tol, self.psi,
                                              self.pos, self.elements, piece_max, step / (1 + margin))
        return self.feed_tubes[key]


def piece_tube(model: RobotModel, chunk: list[int], els: list[PathElement], origin: np.ndarray, tol: float,
               psi: float, pos: np.ndarray, elements: list[PathElement], piece_max: float | np.ndarray,
               unit: np.ndarray | None = None) -> Tube:
    """The tube of a piece, starting where the robot is, its reach checked (``unit``: per move
    its cells of whole samples' travel, :func:`planner.contour.tube.sample_split`)."""
    t = tube(els, origin, tol, psi, piece_max, unit)
    t.element = np.asarray(chunk)[t.element]
    # the first point: where the robot is (within half the tolerance of the path's start, a few
    # um after a move there); the first two cells (the lead cell, held one sample, and the next)
    # are widened to the hull of themselves and a disk of START_ROOM_M about it: the robot at rest
    # there, its forces rising at a bounded rate, moves a few um only in the first samples of a
    # fine sample time (the hull stays within the tolerance: the point is within half of it)
    here = [float(pos[0]), float(pos[1]), psi]
    t.segments[0] = Segment.model_validate({"lower": here, "upper": here})
    import shapely  # loaded on first use (planner._lazy)

    ring = pos + START_ROOM_M * np.column_stack((np.cos(_RING), np.sin(_RING)))
    for k in (1, 2):
        if k < len(t.segments) - 1 and t.segments[k].polygon is not None:
            pts = shapely.multipoints(np.vstack((np.asarray(t.segments[k].polygon, float), ring)))
            poly = shapely.get_coordinates(shapely.get_exterior_ring(shapely.convex_hull(pts)))[:-1]
            lo, hi = poly.min(axis=0), poly.max(axis=0)
            t.segments[k] = Segment.model_validate({"lower": [lo[0], lo[1], psi], "upper": [hi[0], hi[1], psi],
                                                    "polygon": poly.tolist()})
    if len(t.segments) > MAX_SEGMENTS:
        raise PlannerError("too_large", f"line {els[0].line}: the pass needs {len(t.segments)} tube cells at a "
                           f"tolerance of {tol * 1e3:g} mm, more than the limit of {MAX_SEGMENTS}; split the pass "
                           "or give a larger tolerance_m", "program")
    try:
        check_segments(model, t.segments)
    except PlannerError as err:
        k = int(err.field.split("[")[1].split("]")[0]) if err.field and err.field.startswith("segments[") else 0
        line = elements[int(t.element[min(k, len(t.element) - 1)])].line
        raise PlannerError(err.code, f"line {line}: the path leaves the robot's reach at origin "
                           f"[{origin[0]:g}, {origin[1]:g}] m: {err.message}", "program") from None
    return t


def counts_of(res: PlanResult, n: int) -> np.ndarray:
    """The sample counts of the ``n`` segments a plan ran (its ``segment_samples``, else its
    ``samples_per_segment`` each)."""
    ss = res.settings.segment_samples
    return np.asarray(ss if ss is not None else [res.settings.samples_per_segment] * n, np.int64)


def segment_of(counts: np.ndarray, K: int) -> np.ndarray:
    """Segment index of every sample 0..K-1 (sample 0: the start point; past the sequence: the end point)."""
    seg = np.repeat(np.arange(len(counts)), counts)
    idx = np.clip(np.arange(K) - 1, 0, len(seg) - 1)
    out = seg[idx]
    out[0] = 0
    return out


def measure_deviation(pose: np.ndarray, elem: np.ndarray, geo: PathGeometry, tol: float) -> np.ndarray:
    """Per sample: the largest distance from the programmed path of the sample and of the
    straight move to the next, measured on points ``h = tol / 10`` apart along the move plus
    ``h / 2`` (the distance is 1-Lipschitz, so this bounds the maximum from above; the cells
    keep 0.95 tol, so the bound stays within the tolerance) [m]; the moves whose bound exceeds
    the largest distance measured are measured again on points ``h / 8`` apart, and those still
    above it on points ``h / 64`` apart (:data:`CHORD_ROUNDS`: the pass's largest figure is
    within ``h / 128`` of the true maximum, 4e-8 m at a tolerance of 0.05 mm; a round of more
    than :data:`CHORD_POINTS_MAX` points is not measured, the figure then within ``h / 16``).
    Candidates: the elements of both ends and those within :data:`NEAR_TOLERANCES` tolerances
    of them along the pass (a move shorter than the tolerance may be nearer than its
    neighbour; at most :data:`NEAR_MAX` candidates, beyond which the figure can only be too
    large)."""
    K = len(pose)
    h = tol / 10
    lo, hi = geo.near(NEAR_TOLERANCES * tol)
    first = np.minimum(lo[elem[:-1]], lo[elem[1:]])
    last = np.maximum(hi[elem[:-1]], hi[elem[1:]])
    width = int(min(int((last - first).max(initial=0)) + 1, NEAR_MAX))
    cand = np.minimum(first[:, None] + np.arange(width), last[:, None])
    a, b = pose[:-1], pose[1:]
    dev = np.zeros(K)
    seen, bound = _chords(a, b, cand, geo, h)
    dev[:-1] = bound
    top = float(seen.max(initial=0.0))
    for _ in range(CHORD_ROUNDS):
        again = np.nonzero(dev[:-1] > top + 1e-12)[0]
        if not again.size or np.sum(np.hypot(*(b[again] - a[again]).T)) * 8 / h > CHORD_POINTS_MAX:
            break
        h /= 8
        seen_again, dev[again] = _chords(a[again], b[again], cand[again], geo, h)
        top = max(top, float(seen_again.max()))
    e = int(elem[-1])
    end = geo.distance(pose[-1:], np.minimum(lo[e] + np.arange(min(hi[e] - lo[e] + 1, NEAR_MAX)), hi[e])[None, :])
    dev[-1] = max(dev[-1], float(end[0]))
    return dev


def _chords(a: np.ndarray, b: np.ndarray, cand: np.ndarray, geo: PathGeometry, h: float
            ) -> tuple[np.ndarray, np.ndarray]:
    """Per straight move ``a -> b``: the largest distance to the candidate elements ``cand``
    on points at most ``h`` apart, and that plus ``h / 2`` where the move has more than one
    point (a bound from above) [m]."""
    L = np.hypot(*(b - a).T)
    m = np.maximum(np.ceil(L / h).astype(np.int64), 1) + 1
    owner = np.repeat(np.arange(len(a)), m)
    start = np.repeat(np.cumsum(m) - m, m)
    frac = (np.arange(owner.size) - start) / np.repeat(m - 1, m)
    pts = a[owner] + frac[:, None] * (b - a)[owner]
    d = geo.distance(pts, _nearest_only(a, b, cand, geo)[owner])
    seen = np.maximum.reduceat(d, np.cumsum(m) - m)  # each move's points side by side (m >= 2)
    return seen, seen + np.where(m > 1, 0.5 * h, 0.0)


def _to_segments(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance of the points ``p`` to the segments ``a b`` (any matching shapes (..., 2)) [m]."""
    ab, ap = b - a, p - a
    t = np.clip((ap[..., 0] * ab[..., 0] + ap[..., 1] * ab[..., 1])
                / np.maximum(ab[..., 0] * ab[..., 0] + ab[..., 1] * ab[..., 1], 1e-300), 0.0, 1.0)
    return np.hypot(ap[..., 0] - t * ab[..., 0], ap[..., 1] - t * ab[..., 1])


def _nearest_only(a: np.ndarray, b: np.ndarray, cand: np.ndarray, geo: PathGeometry) -> np.ndarray:
    """``cand`` (N, C) with the candidates that cannot be the nearest anywhere on the move
    ``a -> b`` replaced by one that can (rows sorted: :meth:`PathGeometry.distance` measures
    a row's repeats once). A candidate is dropped where its distance to the move (a lower
    bound: segment to segment for a line, to the circle for an arc) exceeds, by 1e-12 m, the
    largest distance along the move of another candidate (a bound from above: for a line the
    larger of the ends', the distance to a segment being convex along a line; for an arc the
    ends' mean plus half the move's length, the distance being 1-Lipschitz); the distance to
    the union, the least of the candidates', is then the same at every point."""
    cand = np.clip(np.asarray(cand), 0, geo.n - 1)
    N, C = cand.shape
    if C < 2 or N == 0:
        return cand
    A, B = a[:, None, :], b[:, None, :]
    da = geo.distance(np.repeat(a, C, axis=0), cand.reshape(-1, 1)).reshape(N, C)
    db = geo.distance(np.repeat(b, C, axis=0), cand.reshape(-1, 1)).reshape(N, C)
    L = np.hypot(*(b - a).T)[:, None]
    arc = geo.arc[cand]
    upper = np.where(arc, 0.5 * (da + db + L), np.maximum(da, db))
    p, q = geo.p0[cand], geo.p1[cand]

    def cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]

    ab, pq = B - A, q - p
    crossing = (cross(ab, p - A) * cross(ab, q - A) <= 0) & (cross(pq, A - p) * cross(pq, B - p) <= 0)
    low_line = np.where(crossing, 0.0, np.minimum(np.minimum(da, db), np.minimum(_to_segments(p, A, B),
                                                                                  _to_segments(q, A, B))))
    c, r = geo.c[cand], geo.r[cand]
    rho_min = _to_segments(c, A, B)
    rho_max = np.maximum(np.hypot(*(A - c).transpose(2, 0, 1)), np.hypot(*(B - c).transpose(2, 0, 1)))
    low_arc = np.maximum(np.maximum(rho_min - r, r - rho_max), 0.0)
    lower = np.where(arc, low_arc, low_line)
    best = np.argmin(upper, axis=1)
    drop = lower > upper[np.arange(N), best][:, None] + 1e-12
    return np.sort(np.where(drop, cand[np.arange(N), best][:, None], cand), axis=1)
