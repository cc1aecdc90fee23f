"""The live cursor readout: the plane point (x, y) [m] under the mouse, and where it snaps.

viser sends the server scene clicks, rectangle selections and drags, but no pointer
*moves*, so a live readout cannot be computed on the server. It is computed in the
browser instead, by a small script in an HTML widget of the panel: on every pointer move
over the 3-D view it casts the ray through the pointer with the camera the server last
heard from this tab (position, orientation, vertical field of view; sent with the widget
as ``data-*`` attributes and updated whenever the camera moves) and intersects it with the
plane z = 0, the same map as :func:`app.editor._geometry.screen_to_plane`. The snapping
grid (step, origin) rides along, so the readout also shows the grid point a drag or a
drawn rectangle would snap to. The script installs its one listener once per page (a
re-render of the widget only refreshes the data it reads).

Units: m.
"""

from __future__ import annotations

import html
import json

__all__ = ["CursorReadout", "readout_html"]

# Runs in the page: installed once, reads the newest data-* of #rangeplan-cursor per move.
_SCRIPT = r"""
(function () {
  var w = window;
  var el = document.getElementById('rangeplan-cursor');
  if (el && w.__rangeplanCursorText) { el.querySelector('.xy').textContent = w.__rangeplanCursorText; }
  if (w.__rangeplanCursor) return;
  w.__rangeplanCursor = true;
  function f(v) { v = Math.abs(v) < 5e-5 ? 0 : v; return (v < 0 ? '\u2212' : '') + Math.abs(v).toFixed(4); }
  document.addEventListener('pointermove', function (e) {
    var el = document.getElementById('rangeplan-cursor');
    if (!el || !el.dataset.cam) return;
    // over the 3-D view only: its canvas (or the overlay canvas of the same size on top of it),
    // not the panel, a plot (small canvases) or a label
    var t = e.target;
    if (!t || t.tagName !== 'CANVAS') return;
    var r = t.getBoundingClientRect();
    if (r.width * r.height < 0.25 * window.innerWidth * window.innerHeight) return;
    var c = JSON.parse(el.dataset.cam), q = c.wxyz, W = q[0], X = q[1], Y = q[2], Z = q[3];
    var R = [[1 - 2 * (Y * Y + Z * Z), 2 * (X * Y - Z * W), 2 * (X * Z + Y * W)],
             [2 * (X * Y + Z * W), 1 - 2 * (X * X + Z * Z), 2 * (Y * Z - X * W)],
             [2 * (X * Z - Y * W), 2 * (Y * Z + X * W), 1 - 2 * (X * X + Y * Y)]];
    var k = Math.tan(c.fov / 2), a = r.width / r.height;
    var d = [(2 * (e.clientX - r.left) / r.width - 1) * k * a, (2 * (e.clientY - r.top) / r.height - 1) * k, 1];
    var D = [0, 1, 2].map(function (i) { return R[i][0] * d[0] + R[i][1] * d[1] + R[i][2] * d[2]; });
    if (Math.abs(D[2]) < 1e-12) return;
    var s = -c.position[2] / D[2];
    if (s <= 0) return;
    var x = c.position[0] + s * D[0], y = c.position[1] + s * D[1];
    var text = 'x ' + f(x) + ' m, y ' + f(y) + ' m';
    var g = el.dataset.grid ? JSON.parse(el.dataset.grid) : null;
    if (g && g.step > 0) {
      var sx = g.origin[0] + Math.round((x - g.origin[0]) / g.step) * g.step;
      var sy = g.origin[1] + Math.round((y - g.origin[1]) / g.step) * g.step;
      text += '  \u2192 snaps to ' + f(sx) + ', ' + f(sy);
    }
    w.__rangeplanCursorText = text;
    el.querySelector('.xy').textContent = text;
  }, {capture: true, passive: true});  // capture: the view stops the event from bubbling
})();
"""


def readout_html(camera: dict | None, grid: dict | None) -> str:
    """The widget's HTML: the readout line with the camera (``position``, ``wxyz``,
    ``fov`` [m, -, rad]) and the snapping ``grid`` (``step``, ``origin`` [m]) as data."""
    cam = html.escape(json.dumps(camera), quote=True) if camera else ""
    grd = html.escape(json.dumps(grid), quote=True) if grid else ""
    script = html.escape(_SCRIPT, quote=True)
    return (f"<div id='rangeplan-cursor' data-cam=\"{cam}\" data-grid=\"{grd}\" "
            "style='font-size:0.8em;margin:0 0.75em 0.4em;font-variant-numeric:tabular-nums'>"
            "Cursor: <span class='xy'>move the mouse over the view</span></div>"
            f"<img src='data:,' alt='' style='display:none' onerror=\"{script}\">")


class CursorReadout:
    """The readout widget of one tab (``gui`` is that tab's ``client.gui``)."""

    def __init__(self, gui):
        self._camera: dict | None = None
        self._grid: dict | None = None
        self.widget = gui.add_html(readout_html(None, None))

    def set_camera(self, position, wxyz, fov: float) -> None:
        """The tab's camera moved: position [m], orientation (w, x, y, z), vertical fov [rad]."""
        camera = {"position": [round(float(v), 6) for v in position], "wxyz": [round(float(v), 8) for v in wxyz],
                  "fov": round(float(fov), 6)}
        if camera != self._camera:
            self._camera = camera
            self.widget.content = readout_html(self._camera, self._grid)

    def set_grid(self, step: float | None, origin) -> None:
        """The snapping grid: ``step`` [m] (None: snapping off) from ``origin`` (x, y) [m]."""
        grid = None if not step else {"step": float(step), "origin": [float(origin[0]), float(origin[1])]}
        if grid != self._grid:
            self._grid = grid
            self.widget.content = readout_html(self._camera, self._grid)
