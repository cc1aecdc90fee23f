"""``program`` feed: a small excess over F under the tool-speed rows is answered by lowering the
rows, not by a sample more per catch-up run (issue 35 goal 2, branch feedcap4).

The rows (``settings.tool_speed_max_m_s``) are a polygon inside the circle of their limit
(32 sides since branch feedcap6, 16 before): along its vertex directions the tool reaches the
limit, ``FEED_SPEED_ROOM`` F (1.0048 F; with the 16-gon 1.015 F), along its sides F. On an arc the
controller's catch-ups pass the vertex directions and run over F (fusion360's pass 1: its
semicircle after a 90-degree corner, 0.48 %; with the 16-gon 1.5 %); a sample more in each such
run cost that 0.3 s pass 12 ms (2.6 %), the rows lowered by the excess cost nothing.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import planner.contour.search as search
from planner.contour import plan_contour
from tests.test_contour_arrival import F_TOL
from tests.test_contour_feed import chord_feed_ratio, feed_by_line

CAM = Path(__file__).resolve().parent / "data" / "cam"


@pytest.fixture(scope="module")
def fusion():
    """fusion360 in the ``program`` feed at the defaults, every candidate plan of its pieces
    recorded: (piece, tool-speed rows' limit, sample counts, plan or None, its largest excess)."""
    text = (CAM / "fusion360.nc").read_text()
    seen: list[tuple[str, float | None, int, object, float]] = []
    attempt = search.TimingSearch.attempt

    def recorded(self, t, counts):
        res = attempt(self, t, counts)
        over = np.nan
        if res is not None:
            over = float(search.overspeed_of(res, counts, np.minimum(self.feed_on(t), self.zcap_on(t))).max())
        seen.append((self.name, self.plan_st.tool_speed_max_m_s, int(counts.sum()), res, over))
        return res

    mp = pytest.MonkeyPatch()
    mp.setattr(search.TimingSearch, "attempt", recorded)
    try:
        res = plan_contour({"program": text, "origin": "fit", "feed": "program"})
    finally:
        mp.undo()
    return text, res, seen


def test_a_small_excess_under_the_rows_lowers_them_and_keeps_the_samples(fusion):
    """fusion360 pass 1 (a 2 mm line, a semicircle after a 90-degree corner, a 2 mm line): its
    first candidate under the rows runs over F by at most FEED_ROWS_LOWER_MAX, on the arc; the
    plan kept has the same sample counts under lower rows, so the pass takes the first
    candidate's time, and no sample is faster than F."""
    text, res, seen = fusion
    piece = [s for s in seen if s[0] == "line 29"]
    name, limit0, n0, first, over0 = piece[0]
    assert first is not None and limit0 is not None
    assert 1.0 < over0 <= search.FEED_ROWS_LOWER_MAX  # a catch-up over F under the rows
    kept = [s for s in piece if s[3] is not None and s[4] <= 1.0]
    assert kept, "no candidate within F"
    _, limit, n, plan, _ = kept[0]
    assert n == n0 and limit is not None and limit < limit0  # the same counts, lower rows
    c = res.contour
    assert c is not None
    assert c.passes[1].time_s == pytest.approx(float(first.time[-1]), abs=1e-9)
    assert c.passes[1].max_feed_ratio <= 1.0
    # F never exceeded while cutting, from the sampled tool point (what the exported program runs)
    assert chord_feed_ratio(res, text) <= 1 + F_TOL


def test_rows_not_lowered_where_the_first_candidate_is_within_F(fusion):
    """fusion360 pass 0 (its first candidate within F under the rows): planned once, the rows at
    FEED_SPEED_ROOM times F, none lowered."""
    _, res, seen = fusion
    piece = [s for s in seen if s[0] == "line 19"]
    assert len(piece) == 1 and piece[0][4] <= 1.0
    top = max(feed_by_line((CAM / "fusion360.nc").read_text()).values())
    assert piece[0][1] == pytest.approx(top * search.FEED_SPEED_ROOM)
