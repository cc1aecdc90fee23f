"""A headless viser client for the editor's server-side tests: it opens the page's websocket
(the subprotocol of this viser version), reports a camera (which is when viser counts a
client as connected and the editor opens its session), and can send what a browser sends
when a person types into a field or clicks a button. The server's messages are read and
dropped. Browser-level behaviour (rendering, real keystrokes) is in test_editor_browser.py.
"""

from __future__ import annotations

import threading

import msgspec
import viser
from viser import _messages as vm
from websockets.sync.client import connect


class HeadlessClient:
    """One tab without a browser, connected to the viser server at ``port``."""

    def __init__(self, port: int):
        self.ws = connect(f"ws://127.0.0.1:{port}/", subprotocols=[f"viser-v{viser.__version__}"], max_size=None,
                          open_timeout=30)
        self.received = 0
        self._reader = threading.Thread(target=self._drain, daemon=True)
        self._reader.start()
        self._send(vm.ViewerCameraMessage(wxyz=(0.0, 1.0, 0.0, 0.0), position=(0.0, 0.0, 1.0), fov=1.0, near=0.01,
                                          far=100.0, image_height=900, image_width=1400, look_at=(0.0, 0.0, 0.0),
                                          up_direction=(0.0, 1.0, 0.0)))

    def _drain(self) -> None:
        try:
            while True:
                self.ws.recv()
                self.received += 1
        except Exception:  # closed
            return

    def _send(self, message) -> None:
        self.ws.send(msgspec.msgpack.encode(message.as_serializable_dict()))

    def type(self, handle, text: str) -> None:
        """What the browser sends when the person changes a GUI input to ``text`` (or value)."""
        self._send(vm.GuiUpdateMessage(handle._impl.uuid, {"value": text}))

    def click(self, button) -> None:
        """What the browser sends for a click on a GUI button."""
        self._send(vm.GuiUpdateMessage(button._impl.uuid, {"value": True}))

    def close(self) -> None:
        self.ws.close()
