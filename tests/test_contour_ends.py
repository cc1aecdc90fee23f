"""A cut piece's first and last samples (issue 35 goals 1 and 2, branch fixedsamples).

The range sequence of a piece starts with its start point and ends with its end point. Held one
sample, the start point pinned sample 1 where sample 0 already is: the drives' first force,
which the force-rate limit lets rise within the first sample, had to wait a sample, and every
piece lost one (dxf2gcode's circle in ``fastest``: 0.2 N in the first sample, 9 N, the limit's
step, only in the second). The end point's sample pinned a second sample where the end's lead
cell pins one already, so a robot that had settled there was kept one sample more (pcb_gcode's
circle in ``program`` feed: within 4 um of its end at 0.69 mm/s, settled, a sample before its
plan ended). Checked here on the CAM samples (tests/data/cam), from the joined result's arrays:
each pass's tool leaves its start in the first sample with its first force stepped up near the
force-rate limit, and where a pass ends, the robot was not settled a sample earlier; both
feeds within F, the tolerance and the drive limits as before.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from planner.contour import plan_contour
from planner.contour.defaults import drive_jerk
from planner.contour.plan import cut_settle
from planner.model import load_robot
from planner.schema.limits import DEFAULT_FORCE_RISE_S

CAM = Path(__file__).resolve().parent / "data" / "cam"


def _runs(res) -> list[tuple[int, int]]:
    """The joined plan's cutting runs [a, b): sample a - 1 is where the pass starts (the
    last sample of the part before, at rest), b - 1 its last."""
    cut = np.asarray(res.contour.cutting, int)
    edges = np.flatnonzero(np.diff(np.concatenate(([0], cut, [0]))))
    assert len(edges) == 2 * len(res.contour.passes), "one cutting run a pass"
    return [(int(edges[2 * k]), int(edges[2 * k + 1])) for k in range(len(res.contour.passes))]


@pytest.fixture(scope="module", params=[("pcb_gcode.ngc", "program"), ("dxf2gcode.ngc", "fastest")],
                ids=["pcb_gcode-program", "dxf2gcode-fastest"])
def planned(request):
    name, feed = request.param
    res = plan_contour({"program": (CAM / name).read_text(), "origin": "fit", "feed": feed})
    return feed, res


def test_the_tool_leaves_each_pass_start_in_the_first_sample(planned):
    _, res = planned
    model = load_robot("moving-slide")
    step = np.asarray(model.force_max, float) / DEFAULT_FORCE_RISE_S * res.settings.Ts  # the largest force step
    f = np.asarray(res.drives.force, float)
    for a, _ in _runs(res):
        s0 = a - 1
        # the force held over the first sample (the joined row at the shared start sample is the
        # pass's first): stepped up, not held at zero for a sample
        assert np.abs(f[s0]).max() > 0.05 * step.max(), (s0, f[s0])
        moved = float(np.hypot(*(res.pose[s0 + 1, :2] - res.pose[s0, :2])))
        assert moved > 1e-6, f"the tool at the start for a sample more (moved {moved:.2e} m)"


def test_no_settled_sample_is_held_at_a_pass_end(planned):
    feed, res = planned
    tol = res.contour.tolerance_m
    model = load_robot("moving-slide")
    settle = cut_settle(res.settings, tol, drive_jerk(model, res.settings))
    speed = np.hypot(*np.asarray(res.velocity)[:, :2].T)
    for k, (_, b) in enumerate(_runs(res)):
        end = res.pose[b - 1, :2]
        last = b - 1
        # the pass ends settled: within the settle position of where it stops and slow
        assert speed[last] <= settle["settle_speed_m_s"] * (1 + 1e-9)
        before = last - 1
        held = (np.hypot(*(res.pose[before, :2] - end)) < settle["settle_position_m"]
                and speed[before] < settle["settle_speed_m_s"])
        if feed == "program":  # pcb_gcode's passes settle on the end's lead cell: no sample more
            assert not held, f"pass {k}: settled at sample {before} and held to {last}"


def test_the_limits_hold(planned):
    feed, res = planned
    c = res.contour
    assert res.metrics.within_limits
    assert c.max_deviation_m <= c.tolerance_m and c.max_path_deviation_m <= c.tolerance_m
    if feed == "program":
        assert max(p.max_feed_ratio for p in c.passes) <= 1.0 + 1e-6
