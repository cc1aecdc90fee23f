"""Browser corridor editor (viser).

A person designs a corridor in the browser and sees the robot move through it; the
editor's state is a plan request in the one JSON shape. The parts:

- :mod:`._editor`: :class:`Editor`, which ties the parts together, and :func:`start_editor`
- :mod:`._state`: the edited request and the newest plan outcome (no viser)
- :mod:`._planning`: the re-plan worker; the only editor module that imports ``planner``
- :mod:`._scene`: the 3-D scene, its nodes created once and updated in place
- :mod:`._gui`: the control panel and the playback
- :mod:`._files`: store, request JSON and trajectory CSV
- :mod:`._geometry`: numpy-only geometry of what is drawn
- :mod:`._gate`: the access rules (:mod:`app.security`) on the editor's port

Entry point: :func:`start_editor` (used by ``app.server.serve``).
"""

from ._editor import Editor, start_editor
from ._gate import start_guarded
from ._planning import use_pool

__all__ = ["Editor", "start_editor", "start_guarded", "use_pool"]
