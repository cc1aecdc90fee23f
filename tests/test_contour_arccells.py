"""``fastest`` on arcs the drives bound below one tube chord per sample (issue 35 goal 1,
:meth:`planner.contour.search.TimingSearch.arc_cells`): the sample time rule leaves such arcs
room where no pass mixes lines and arcs (:data:`planner.contour.defaults.ARC_CELL_TS_FRACTION`),
the re-cut tube's arc cells are one sample's travel at the speed asked and still within the
sagitta, and the re-cut cells cut an isolated circle faster than the chords did at the same
sample time, within the tolerance both ways and the drive limits. (Against the exact path's
third-order optimum: benchmarks/bench_contour_feed.py --feed fastest.)"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from planner.contour import plan_contour
from planner.contour.defaults import (
    ARC_CELL_TS_FRACTION,
    TS_FLOOR_S,
    TS_STEP_S,
    arc_speed,
    drive_acceleration,
    drive_jerk,
)
from planner.contour.passes import TubeSizes
from planner.contour.search import TimingSearch
from planner.contour.tube import SAGITTA_FRACTION
from planner.model import load_robot
from tests.test_contour_defaults import settings_of

CAM = Path(__file__).parent / "data" / "cam"


def _needs(program, tol, model, st):
    """Per arc: (its chord of the sagitta over the speed it asks [s], chord [m], speed [m/s])."""
    a, jerk = drive_acceleration(model), drive_jerk(model, st)
    s_a = SAGITTA_FRACTION * tol
    out = []
    for b in program.passes:
        for e in b.elements:
            if e.kind == "arc" and e.radius_m:
                chord = 2 * math.sqrt(2 * e.radius_m * s_a - s_a * s_a)
                v = arc_speed(e, a, jerk, float(np.min(model.speed_max)), "fastest")
                out.append((chord / v, chord, v))
    return out


@pytest.mark.parametrize("name", ["dxf2gcode.ngc", "pcb_gcode.ngc"])
def test_arcs_alone_ts_leaves_the_arc_room(name):
    """A program whose passes do not mix lines and arcs: the binding arc's chord per sample is
    at least 1 / ARC_CELL_TS_FRACTION its speed (room for cells at the drives' speed), and a
    step more would not be (or the floor binds)."""
    model = load_robot("moving-slide")
    st, program, tol = settings_of({"program": (CAM / name).read_text(), "feed": "fastest"})
    assert not any({e.kind for e in b.elements} >= {"arc", "line"} for b in program.passes)
    need = min(n for n, _, _ in _needs(program, tol, model, st))
    assert TS_FLOOR_S <= st.Ts <= ARC_CELL_TS_FRACTION * need + 1e-12 or st.Ts == TS_FLOOR_S
    assert st.Ts + TS_STEP_S > ARC_CELL_TS_FRACTION * need or st.Ts == TS_FLOOR_S
    assert need / st.Ts > 1.0  # one chord per sample faster than the arc asks


def _search(name: str):
    model = load_robot("moving-slide")
    st, program, tol = settings_of({"program": (CAM / name).read_text(), "feed": "fastest"})
    els = [e for e in program.passes[-1].elements if e.length_m > 1e-12]
    chunk = list(range(len(els)))
    origin = np.array([0.0, 0.0])  # the pass about the base's centre: the circle's cells only
    centre = np.asarray(model.base, float).mean(axis=0) - np.mean([e.start for e in els], axis=0)
    sizes = TubeSizes(model, st, chunk, els, centre + origin, tol, 0.0, centre + np.asarray(els[0].start), els)
    return TimingSearch(model, st, sizes, chunk, els, None, None), st, tol, els, model


@pytest.mark.parametrize("name", ["dxf2gcode.ngc", "pcb_gcode.ngc"])
def test_recut_arc_cells_are_a_sample_at_the_speed_and_within_the_sagitta(name):
    """The re-cut tube (:meth:`TimingSearch.arc_tube`): on each arc the drives bound, every
    cell at most ``kappa v Ts`` and all alike but the lead cells and their neighbours (one sample each at one speed),
    each chord within the sagitta of the arc; as many cells as samples at that speed (the
    chords of the sagitta where they are shorter)."""
    search, st, tol, els, _ = _search(name)
    v = search.arc_speeds()
    assert (v > 0).all()  # a circle alone: every arc bound by the drives at the chosen Ts
    s_a = SAGITTA_FRACTION * tol
    for kappa in (1.0, 1.05):
        t = search.arc_tube(0.1, kappa)
        assert t is not None
        for i, e in enumerate(els):
            assert e.radius_m is not None
            cells = (t.element == i) & (t.length > 0) & ~t.lead
            ln = t.length[cells]
            assert ln.max() <= kappa * v[i] * st.Ts * (1 + 1e-9)
            inner = ln[1:-1]  # the first and the last: the lead cells' remainders
            assert inner.max() - inner.min() < 1e-6 * inner.max()
            chord = 2 * math.sqrt(2 * e.radius_m * s_a - s_a * s_a)
            assert ln.max() <= chord * (1 + 1e-9)
            assert cells.sum() == math.ceil(e.length_m / min(kappa * v[i] * st.Ts, chord) - 1e-9)
            sag = e.radius_m - math.sqrt(e.radius_m ** 2 - (ln.max() / 2) ** 2)
            assert sag <= s_a * (1 + 1e-9)


@pytest.mark.slow
def test_recut_cells_cut_the_circle_faster_within_tolerance(monkeypatch):
    """dxf2gcode's circle (r 4 mm) at the chosen sample time: the re-cut cells cut it at least
    3 % faster than the chords of the sagitta (the search without them) at the same sample time
    and horizon, within the tolerance both ways and the drive limits, its top speed within the
    drives' turn speed on the circle (times ARC_KAPPA_MAX)."""
    from planner.contour.search import ARC_KAPPA_MAX

    body = {"program": (CAM / "dxf2gcode.ngc").read_text(), "origin": "fit", "feed": "fastest"}
    new = plan_contour(body)
    monkeypatch.setattr(TimingSearch, "arc_speeds", lambda self: np.zeros(len(self.els)))
    old = plan_contour(body)
    assert new.contour is not None and old.contour is not None
    assert new.settings.Ts == old.settings.Ts and new.settings.N == old.settings.N
    p_new, p_old = new.contour.passes[0], old.contour.passes[0]
    assert p_new.time_s < 0.97 * p_old.time_s
    assert p_new.max_deviation_m <= new.contour.tolerance_m
    assert p_new.max_path_deviation_m <= new.contour.tolerance_m
    assert new.metrics.within_limits
    model = load_robot("moving-slide")
    st, program, tol = settings_of({"program": body["program"], "feed": "fastest"})
    v = max(s for _, _, s in _needs(program, tol, model, st))
    assert p_new.max_speed_m_s <= ARC_KAPPA_MAX * v
