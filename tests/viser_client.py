"""A headless viser client for the editor's server-side tests: it opens the page's websocket
(the subprotocol of this viser version), reports a camera (which is when viser counts a
client as connected and the editor opens its session), and can send what a browser sends
when a person types into a field or clicks a button. The server's messages are read and
dropped. Browser-level behaviour (rendering, real keystrokes) is in test_editor_browser.py.
"""

from __future__ import annotations

import threading

import msgspec
import numpy as np
import viser
import zstandard
from viser import _messages as vm
from websockets.sync.client import connect


class HeadlessClient:
    """One tab without a browser, connected to the viser server at ``port``."""

    def __init__(self, port: int):
        self.ws = connect(f"ws://127.0.0.1:{port}/", subprotocols=[f"viser-v{viser.__version__}"], max_size=None,
                          open_timeout=30)
        self.received = 0
        self.scene = SceneMirror()
        self._reader = threading.Thread(target=self._drain, daemon=True)
        self._reader.start()
        self._send(vm.ViewerCameraMessage(wxyz=(0.0, 1.0, 0.0, 0.0), position=(0.0, 0.0, 1.0), fov=1.0, near=0.01,
                                          far=100.0, image_height=900, image_width=1400, look_at=(0.0, 0.0, 0.0),
                                          up_direction=(0.0, 1.0, 0.0)))

    def _drain(self) -> None:
        try:
            while True:
                self.scene.feed(self.ws.recv())
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


class SceneMirror:
    """The scene as this client received it: every scene node's newest properties and
    visibility, decoded from viser's wire format (zstd-compressed msgpack followed by the raw
    8-byte-aligned numpy buffers its placeholders ``{"__binary_index", "dtype"}`` point at)."""

    def __init__(self):
        self.props: dict[str, dict] = {}
        self.visible: dict[str, bool] = {}
        self.messages = 0
        self.watchers: list = []  #: callables(mirror) run after every received window, under the lock
        self._lock = threading.RLock()

    def feed(self, raw) -> None:
        if not isinstance(raw, bytes) or len(raw) < 16:
            return
        size = int.from_bytes(raw[8:16], "little")
        inner = msgspec.msgpack.decode(zstandard.ZstdDecompressor().decompress(raw[16:16 + size]))
        offset, buffers = 16 + size, []
        for n in inner.get("binaryBufferLengths", ()):
            offset += (8 - offset % 8) % 8
            buffers.append(raw[offset:offset + n])
            offset += n

        def resolve(v):
            if isinstance(v, dict) and "__binary_index" in v and "dtype" in v:
                return np.frombuffer(buffers[v["__binary_index"]], dtype=np.dtype(v["dtype"]))
            if isinstance(v, dict):
                return {k: resolve(x) for k, x in v.items()}
            if isinstance(v, list):
                return [resolve(x) for x in v]
            return v

        with self._lock:
            for m in inner.get("messages", ()):
                self.messages += 1
                name = m.get("name") if isinstance(m, dict) else None
                if not isinstance(name, str):
                    continue
                if "props" in m:  # a node created
                    self.props[name] = resolve(m["props"])
                    self.visible.setdefault(name, True)
                elif "updates" in m:
                    updates = resolve(m["updates"])
                    if isinstance(updates, dict):
                        self.props.setdefault(name, {}).update(updates)
                for key in ("position", "wxyz"):  # SetPositionMessage / SetOrientationMessage
                    if key in m:
                        self.props.setdefault(name, {})[key] = np.asarray(m[key], float)
                if "visible" in m:
                    self.visible[name] = bool(m["visible"])
                if m.get("type") == "RemoveSceneNodeMessage":
                    self.props.pop(name, None)
            for watch in self.watchers:  # after each window: what the browser shows between two windows
                watch(self)

    def node(self, name: str) -> dict | None:
        """The newest properties (and position, wxyz) of the node ``name``, or None."""
        with self._lock:
            return dict(self.props[name]) if name in self.props else None

    def mesh(self, name: str) -> tuple[np.ndarray, np.ndarray] | None:
        """Vertices (V, 3) and faces (F, 3) of the mesh node ``name`` as received, or None when
        the node is hidden."""
        with self._lock:
            if not self.visible.get(name, False) or name not in self.props:
                return None
            p = self.props[name]
            return (np.asarray(p["vertices"], float).reshape(-1, 3), np.asarray(p["faces"], np.int64).reshape(-1, 3))

    def lines(self, name: str) -> np.ndarray | None:
        """Segments (M, 2, 3) of the line-segment node ``name`` as received, or None when hidden."""
        with self._lock:
            if not self.visible.get(name, False) or name not in self.props:
                return None
            return np.asarray(self.props[name]["points"], float).reshape(-1, 2, 3)
