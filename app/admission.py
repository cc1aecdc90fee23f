"""Admission to the event loop (issue 15, 21): one new request a turn of the loop, so that
``/health``, ``/ready`` and ``/metrics`` answer within milliseconds under any burst.

The event loop runs its ready callbacks in turns, first come, first served, and looks for
new input only between turns. When 200 clients send their first requests in the same
instant, one turn starts all 200, and each runs until it first waits for something: a
list page is answered in that one go (~1 ms), a plan or a save parses and validates its body
first (~2-3 ms of pydantic). A probe that arrived meanwhile is read after that turn: ``/ready``
took 0.5-1.1 s (tests/test_load.py; the goal is 1 s). Limiting how many requests run at
once does not help: each finishes its part before the next starts.

:class:`AdmissionGate` is an ASGI middleware in front of the access rules, the body limit and
the routes. A request other than :data:`EXEMPT_PATHS` goes on if no request has gone on in
this turn and none is waiting; else it waits, unread (a suspended task costs a turn
nothing), and the next turn lets the first waiting one on. So a turn does the work of one
new request besides the rest of those already under way (answers, hand-overs to workers),
and a probe waits for a few milliseconds. Requests still pass at the speed the loop does
their work: with a backlog the loop only turns more often (a turn costs ~20 us).

Waiting is bounded: with ``queue`` requests waiting, another is answered 503 ``busy`` at
once, with ``Retry-After: 1`` (:data:`RETRY_AFTER_S`): here the first place frees at the next
turn of the loop, within milliseconds, so a second is already the honest upper bound; the
busy answers of the workers (a full plan queue, ``RANGEPLAN_MAX_QUEUE``; jobs on every worker)
say instead when their first slot is expected to free, from the work under way
(:func:`app.routers.deps.busy_retry_after`).
"""

from __future__ import annotations

import asyncio
import json
from collections import deque

__all__ = ["EXEMPT_PATHS", "RETRY_AFTER_S", "Admission", "AdmissionGate"]

#: the ``Retry-After`` of the gate's 503 [s]: the least HTTP can say (a place frees in a turn)
RETRY_AFTER_S = 1

#: answered without waiting: the probes and the metrics a monitor scrapes under load
EXEMPT_PATHS = frozenset({"/health", "/ready", "/metrics"})


class _Turns:
    """One admission a turn of ``loop``; the others wait first come, first served."""

    def __init__(self, loop: asyncio.AbstractEventLoop):
        self.loop = loop
        self.waiters: deque[asyncio.Future] = deque()
        self.admitted = False  # one has gone on in this turn
        self._next_turn = False  # _turn is scheduled

    async def admit(self) -> None:
        if not self.admitted and not self.waiters:
            self.admitted = True
            self._schedule()
            return
        fut = self.loop.create_future()
        self.waiters.append(fut)
        self._schedule()
        await fut  # completed by _turn (cancelled: the client left; _turn skips it)

    def _schedule(self) -> None:
        # call_soon from within a turn runs in the next turn (asyncio runs only the callbacks
        # that were ready when a turn began), after the input read in between
        if not self._next_turn:
            self._next_turn = True
            self.loop.call_soon(self._turn)

    def _turn(self) -> None:
        self._next_turn = False
        self.admitted = False
        while self.waiters:
            fut = self.waiters.popleft()
            if not fut.done():
                fut.set_result(None)  # it runs in the next turn
                self.admitted = True
                break
        if self.admitted:
            self._schedule()


async def _busy(send, message: str) -> None:
    """503 in the API's one error shape (:mod:`app.errors`, written here as ASGI messages)."""
    body = json.dumps({"error": {"code": "busy", "message": message, "field": None}}).encode()
    await send({"type": "http.response.start", "status": 503,
                "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode()),
                            (b"retry-after", str(RETRY_AFTER_S).encode())]})
    await send({"type": "http.response.body", "body": body})


class Admission:
    """The gate's state, one per app (``app.state.admission``: the metrics read :attr:`waiting`)."""

    def __init__(self, queue: int = 1024):
        self.queue = queue
        self._turns: _Turns | None = None  # made on the server's loop, at first use

    @property
    def waiting(self) -> int:
        """Requests waiting now."""
        turns = self._turns
        return len(turns.waiters) if turns is not None else 0

    def turns(self) -> _Turns:
        loop = asyncio.get_running_loop()
        turns = self._turns
        if turns is None or turns.loop is not loop:  # a new loop (a test client's): new turns
            turns = self._turns = _Turns(loop)
        return turns


class AdmissionGate:
    """ASGI middleware: one request (other than :data:`EXEMPT_PATHS`) on a turn of the event
    loop; at most ``admission.queue`` waiting, beyond that 503 ``busy``."""

    def __init__(self, app, admission: Admission | None = None):
        self.app = app
        self.admission = admission if admission is not None else Admission()

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http" or scope.get("path") in EXEMPT_PATHS:
            return await self.app(scope, receive, send)
        turns = self.admission.turns()
        if len(turns.waiters) >= self.admission.queue:
            return await _busy(send, f"{len(turns.waiters)} requests are waiting for the server already; "
                               "retry in a second")
        await turns.admit()
        await self.app(scope, receive, send)
