"""Browser corridor editor (viser).

A person designs a corridor in the browser and sees the robot move through it; the
editor's state is a plan request in the one JSON shape. The parts:

- :mod:`._editor`: :class:`Editor`, the viser server that gives every browser tab its own
  session, and :func:`start_editor`
- :mod:`._session`: :class:`Session`, one tab's editing session: edits, undo, snapping,
  the re-plan, errors; :mod:`._session_segments`: its segment-list edits
- :mod:`._state`: the edited request and the newest plan outcome, and the session's
  read-only views of them (no viser)
- :mod:`._history`: undo / redo steps (no viser)
- :mod:`._planning`: the re-plan worker; the only editor module that imports ``planner``
- :mod:`._scene`: the 3-D scene of one tab, its nodes created once and updated in place
- :mod:`._gui`: the control panel and the playback; :mod:`._gui_segments`: the segment
  boxes' folder; :mod:`._gui_program`: the Files tab's G-code program folder (a CAM program
  opened, placed and contoured: the design is then a contour request); :mod:`._fields`:
  number entry as text; :mod:`._result`: the Result tab's plots and the leg legend;
  :mod:`._cursor`: the live cursor readout
- :mod:`._files`: store, request JSON, G-code programs opened, trajectory CSV and machine files
- :mod:`._geometry`: numpy / shapely geometry of what is drawn, snapping, clipping
- :mod:`._gate`: the access rules (:mod:`app.security`) on the editor's port

Entry point: :func:`start_editor` (used by ``app.server.serve``).
"""

from ._editor import Editor, start_editor
from ._gate import start_guarded
from ._planning import use_pool, use_service
from ._session import Session

__all__ = ["Editor", "Session", "start_editor", "start_guarded", "use_pool", "use_service"]
