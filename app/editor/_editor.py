"""Browser corridor editor (viser): the :class:`Editor` server, one session per tab.

The editor serves a page on which a person designs a corridor (top-down view of the
workspace) and sees the robot move through it. Each browser tab that connects gets its
own editing session (:class:`app.editor._session.Session`: request, undo history, re-plan
worker, scene and panel, all local to that tab); closing the tab ends it. What the tabs
share is the corridor store (save a corridor by name in one tab, load it in another) and
the loaded robots. The editor's state *is* a plan request in the one JSON shape
(:class:`planner.schema.PlanRequest`, with a ``layout`` or a ``segments`` list).

Units: m, rad, s, N. Entry point: :func:`start_editor` (used by ``app.server.serve``).
"""

from __future__ import annotations

import copy
import logging
import threading
import time

import viser

from . import _geometry as geo
from . import _state
from ._planning import RobotCache
from ._scene import EditorScene
from ._session import Session

__all__ = ["DEBOUNCE_S", "Editor", "start_editor"]

log = logging.getLogger("rangeplan.editor")

DEBOUNCE_S = 0.3  #: quiet time after the last edit before a re-plan starts [s]


class Editor:
    """The editor's viser server; every tab that connects gets its own :class:`Session`.

    ``store`` is an :class:`app.storage.Store` (or None: no saving); ``debounce`` [s] is
    the quiet time after an edit before a re-plan starts; ``request`` the design a new
    tab starts from (default :data:`app.editor._state.DEFAULT_REQUEST`).
    """

    def __init__(self, host: str, port: int, store=None, *, debounce: float = DEBOUNCE_S,
                 request: dict | None = None, verbose: bool = False):
        self.store = store
        self.debounce = debounce
        self.initial_request = copy.deepcopy(request if request is not None else _state.DEFAULT_REQUEST)
        self.robots = RobotCache()
        self._sessions: dict[int, Session] = {}
        self._gone: set[int] = set()  # clients that left before their session was built
        self._lock = threading.Condition()
        self._stopped = False
        self.server = viser.ViserServer(host=host, port=port, label="rangeplan editor", verbose=verbose)
        self.host, self.port = host, self.server.get_port()
        self.server.scene.set_up_direction("+z")
        self.server.scene.world_axes.visible = False
        self._place_initial_camera()
        self.robots.of_request(self.initial_request, fallback=True)  # load the robot before the first tab
        self.server.on_client_connect(self._on_connect)
        self.server.on_client_disconnect(self._on_disconnect)

    @property
    def url(self) -> str:
        """The page's address."""
        return f"http://{self.host}:{self.port}/"

    @property
    def sessions(self) -> list[Session]:
        """The open sessions (one per connected tab), oldest first."""
        with self._lock:
            return list(self._sessions.values())

    def session_of(self, client_id: int) -> Session | None:
        """The session of the tab with viser client id ``client_id``."""
        with self._lock:
            return self._sessions.get(client_id)

    def wait_for_sessions(self, n: int, timeout: float = 30.0) -> list[Session]:
        """Wait up to ``timeout`` [s] until at least ``n`` tabs have a session; returns them."""
        end = time.monotonic() + timeout
        with self._lock:
            while len(self._sessions) < n and time.monotonic() < end:
                self._lock.wait(0.05)
            return list(self._sessions.values())

    def stored_changed(self) -> None:
        """Re-read the stored corridors into every tab's list (after a save)."""
        for session in self.sessions:
            session.files.refresh_stored()

    def stop(self) -> None:
        """End every session and stop the viser server."""
        if self._stopped:
            return
        self._stopped = True
        for session in self.sessions:
            session.close()
        for session in self.sessions:
            session.worker.join(timeout=5.0)
        self.server.stop()

    # ------------------------------------------------------------------ tabs
    def _on_connect(self, client) -> None:
        if self._stopped:
            return
        session = Session(self, client, self.initial_request)
        with self._lock:
            gone = client.client_id in self._gone
            if not gone:
                self._sessions[client.client_id] = session
            self._lock.notify_all()
        if gone:
            session.close()

    def _on_disconnect(self, client) -> None:
        with self._lock:
            session = self._sessions.pop(client.client_id, None)
            if session is None:
                self._gone.add(client.client_id)
        if session is not None:
            session.close()

    def _place_initial_camera(self) -> None:
        r = self.initial_request
        layout = r.get("layout")
        if layout is None:
            return
        robot = self.robots.of_request(r, fallback=True)
        centre, half = geo.view_extent(layout["bounds"]["lower"], layout["bounds"]["upper"], robot)
        EditorScene.place_camera(centre, half, None, self.server.initial_camera)


def start_editor(host: str, port: int, store=None, **kwargs) -> Editor:
    """Start the editor's viser server on ``host:port`` (own thread) and return its handle;
    ``handle.stop()`` shuts it down. ``store`` is an :class:`app.storage.Store` (or None:
    no saving); ``kwargs`` go to :class:`Editor`."""
    return Editor(host, port, store, **kwargs)
