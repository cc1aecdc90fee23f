"""The Result tab and the leg-colour legend: which plan is shown, its plots and metrics.

The plots are viser uPlot charts. uPlot treats x as UNIX time by default (the axis read
":00.000 ... 1/1/70"); here the x scale is set to ``time: False`` so the axis shows
seconds. The force axis is scaled to the data (a 10 N force is not drawn flat against
+-150 N limit lines); the limits are dashed lines that come into view when the forces
approach them, and the "plots include the limits" toggle scales the axes to show them
always. After a failed plan the plots are emptied and say which plan failed, so a plot
never stands for a design it was not planned for. Every title names its plan
(``plan #12``, the re-plan generation the status line shows).

Units: s, N, m.
"""

from __future__ import annotations

import html
from typing import TYPE_CHECKING, Any, cast

import numpy as np

if TYPE_CHECKING:
    from ._planning import PlanResult

__all__ = ["LEG_GRADIENT", "PLOT_COLOURS", "ResultPanel", "leg_legend_html", "metrics_markdown"]

PLOT_COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b")
#: colours of a leg in the view, from no force to the force limit (as the scene draws them)
LEG_GRADIENT = ("rgb(60,60,200)", "rgb(255,60,40)")
_LIMIT = {"stroke": "#777", "dash": [5, 4], "width": 1}
_EMPTY = (np.zeros(0), np.zeros(0))


def _range(data: list[np.ndarray], limits: tuple[float, float], include_limits: bool) -> list[float]:
    """A y range [lo, hi] around ``data`` (10 % margin), widened to ``limits`` when asked."""
    values = np.concatenate([np.ravel(d) for d in data]) if data else np.zeros(1)
    lo, hi = float(np.min(values)), float(np.max(values))
    if include_limits:
        lo, hi = min(lo, limits[0]), max(hi, limits[1])
    pad = 0.1 * (hi - lo) if hi > lo else max(abs(hi), 1e-3) * 0.1
    return [lo - pad, hi + pad]


def leg_legend_html(n_legs: int, force_limit: float | None) -> str:
    """The legend of the robot's legs in the view: the colour scale of |drive force| from
    0 to the limit, and that the numbers at the base pivots are the plots' F1, F2, ..."""
    limit = f"{force_limit:.0f} N" if force_limit else "the limit"
    swatches = " ".join(f"<span style='color:{PLOT_COLOURS[i % 6]};font-weight:600'>{i + 1}</span>"
                        for i in range(n_legs))
    return (
        "<div style='font-size:0.8em;line-height:1.35;margin:0 0.75em 0.4em'>"
        f"<div>Leg colour in the view = |drive force|:</div>"
        f"<div style='display:flex;align-items:center;gap:0.4em'><span>0 N</span>"
        f"<span style='flex:1;height:0.7em;border-radius:2px;"
        f"background:linear-gradient(to right,{LEG_GRADIENT[0]},{LEG_GRADIENT[1]})'></span>"
        f"<span>{html.escape(limit)}</span></div>"
        f"<div>Legs are numbered at their base pivots: {swatches} = F1, F2, … in the plots.</div></div>")


class ResultPanel:
    """The Result tab of one session: a header naming the plan shown, the force and
    length plots, the metrics. ``include_limits`` is the toggle's checkbox."""

    def __init__(self, gui):
        self.header = gui.add_markdown("No plan yet.")
        self.include_limits = gui.add_checkbox("Plots include the limits", False,
                                               hint="Scale the axes to the drive-force and stroke limits too "
                                                    "(off: scaled to the data, limits dashed when near)")
        self.force_plot = gui.add_uplot(_EMPTY, ({"label": "t (s)"}, {"label": "F (N)"}), title="Drive forces",
                                        scales=cast(Any, {"x": {"time": False}}), aspect=1.5)
        self.length_plot = gui.add_uplot(_EMPTY, ({"label": "t (s)"}, {"label": "l (m)"}), title="Leg lengths",
                                         scales=cast(Any, {"x": {"time": False}}), aspect=1.5)
        self.metrics = gui.add_markdown("")
        self.plan: int | None = None  #: generation of the plan the plots show (None: none)
        self._last: tuple[PlanResult, Any, int] | None = None
        self.include_limits.on_update(lambda _: self._redraw())

    def _redraw(self) -> None:
        if self._last is not None:
            self.show(*self._last)

    def show(self, result: PlanResult, robot, plan: int) -> None:
        """Plots and metrics of ``result`` (plan ``plan``), for ``robot`` (its limits)."""
        self._last = (result, robot, plan)
        self.plan = plan
        t, force, length = result.time, result.drives.force, result.drives.length
        n = force.shape[1]
        f_max = float(np.min(robot.force_max))
        l_min, l_max = float(np.max(robot.length_min)), float(np.min(robot.length_max))
        wide = bool(self.include_limits.value)

        def series(symbol: str, unit: str, lower: str, upper: str) -> tuple:
            return ({"label": "t (s)"},
                    *({"label": f"{symbol}{i + 1} ({unit})", "stroke": PLOT_COLOURS[i % 6], "width": 1.5}
                      for i in range(n)),
                    {"label": f"{upper} ({unit})", **_LIMIT}, {"label": f"{lower} ({unit})", **_LIMIT})

        def axes(unit_label: str) -> tuple:
            return ({"label": "t (s)", "size": 36}, {"label": unit_label, "size": 52})

        forces = [force[:, i] for i in range(n)]
        lengths = [length[:, i] for i in range(n)]
        self.force_plot.series = series("F", "N", "-limit", "+limit")
        self.force_plot.axes = cast(Any, axes("F (N)"))
        self.force_plot.scales = cast(Any, {"x": {"time": False},
                                            "y": {"range": _range(forces, (-f_max, f_max), wide)}})
        self.force_plot.title = f"Drive forces (N), limit ±{f_max:.0f} N — plan #{plan}"
        self.force_plot.data = (t, *forces, np.full_like(t, f_max), np.full_like(t, -f_max))
        self.length_plot.series = series("l", "m", "min", "max")
        self.length_plot.axes = cast(Any, axes("l (m)"))
        self.length_plot.scales = cast(Any, {"x": {"time": False},
                                             "y": {"range": _range(lengths, (l_min, l_max), wide)}})
        self.length_plot.title = f"Leg lengths (m), stroke {l_min:.3f}…{l_max:.3f} m — plan #{plan}"
        self.length_plot.data = (t, *lengths, np.full_like(t, l_max), np.full_like(t, l_min))
        self.metrics.content = metrics_markdown(result)

    def clear(self, why: str) -> None:
        """Empty the plots and metrics: the newest plan failed (``why`` says which and why)."""
        self._last = None
        self.plan = None
        for plot, name in ((self.force_plot, "Drive forces"), (self.length_plot, "Leg lengths")):
            plot.series = ({"label": "t (s)"}, {"label": "-"})
            plot.data = _EMPTY
            plot.title = f"{name}: no plan"
        self.header.content = why
        self.metrics.content = ""


def metrics_markdown(result: PlanResult) -> str:
    """The result's metrics as a markdown table, with the limits it violates."""
    m = result.metrics
    lines = [
        "| metric | value |", "|---|---|",
        f"| duration | {m.duration_s:.3f} s |",
        f"| end error | {m.end_error_m:.2e} m, {m.end_error_rad:.2e} rad |",
        (f"| max drive force | {m.max_drive_force_n:.1f} N of {m.force_limit_n:.0f} N "
         f"({100 * m.max_force_ratio:.0f} %) |"),
        f"| max drive speed | {m.max_drive_speed_m_s:.3f} m/s ({100 * m.max_speed_ratio:.0f} % of limit) |",
        f"| corridor violation | {m.max_corridor_violation_m:.2e} m |",
        f"| time-indexed range violation | {m.time_indexed_violation_m:.2e} m |",
        f"| stroke violation | {m.max_stroke_violation_m:.2e} m |",
        f"| overshoot | {m.overshoot_m:.2e} m |",
        f"| path length | {m.path_length_m:.3f} m |",
        f"| mode, compute | {result.mode}, {m.compute_ms:.0f} ms |",
    ]
    c = result.contour
    if c is not None:  # a G-code program's plan: G64 P both ways, its time
        lines += [
            f"| tolerance (G64 P) | {c.tolerance_m * 1e3:g} mm |",
            f"| deviation, cut from path / path from cut | {c.max_deviation_m * 1e3:.4f} mm / "
            f"{c.max_path_deviation_m * 1e3:.4f} mm |",
            f"| cycle time, cutting | {c.cycle_time_s:.3f} s, {c.cut_time_s:.3f} s ({len(c.passes)} pass(es)) |",
            f"| program zero (robot frame) | [{c.origin[0]:.4f}, {c.origin[1]:.4f}] m |",
        ]
    warn = []
    if c is not None and c.max_deviation_m > c.tolerance_m:
        warn.append("the cut leaves the tolerance")
    if m.max_force_ratio > 1:
        warn.append("drive force above the limit")
    if m.max_corridor_violation_m > 1e-3:
        warn.append("leaves the corridor by more than 1 mm")
    if m.max_stroke_violation_m > 0:
        warn.append("a leg leaves its stroke")
    if warn:
        lines.append("\n**Violations:** " + "; ".join(warn))
    else:
        lines.append("\nNo violations (forces within limits, corridor kept within 1 mm).")
    return "\n".join(lines)
