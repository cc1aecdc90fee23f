"""Browser corridor editor (viser): see :mod:`app.editor._editor`.

Entry point: :func:`start_editor` (used by ``app.server.serve``).
"""

from ._editor import Editor, start_editor

__all__ = ["Editor", "start_editor"]
