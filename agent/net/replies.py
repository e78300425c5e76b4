"""A query's replies, bounded in number and in time (docs/design.md §3: trust nothing from
the network; every queue bounded, every wait with a deadline).

zenoh hands each reply of a get to a callback on its own thread and calls the handler's
drop when the query is over. :class:`ReplyInbox` is that handler's other side: the
callback only puts a reply in a queue (never blocks, never raises; beyond
:data:`MAX_REPLIES` replies are dropped, so that a flood cannot grow memory), the drop
puts the end, and :meth:`ReplyInbox.stream` yields the replies until the end or until its
deadline passes, whichever comes first. zenoh ends a get at its timeout; a stream it
leaves open (at 100 NAOs under a load of 90, a camera query's stream stayed open 20
minutes, and the agent's main thread with it) ends :data:`REPLY_GRACE` seconds past the
query's timeout, which the caller then reports as a timeout like any other.

Pure Python: ``agent/net/bus.py`` (the one module that imports zenoh) wraps
:meth:`ReplyInbox.put` and :meth:`ReplyInbox.end` in zenoh's callback handler.
"""

from __future__ import annotations

import queue
import time
from collections.abc import Iterator
from typing import Any

#: Replies a query keeps at most (the first usable one is what it wants).
MAX_REPLIES = 64
#: Seconds a query's reply stream may stay open past the query's own timeout.
REPLY_GRACE = 5.0

_END = object()


class ReplyInbox:
    """The replies of one query (module docstring)."""

    def __init__(self, limit: int = MAX_REPLIES) -> None:
        if limit < 1:
            raise ValueError(f"limit must be >= 1, got {limit}")
        self._box: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self._left = iter(range(limit))

    def put(self, reply: Any) -> None:
        """One reply (zenoh's thread: never blocks, never raises; beyond the limit, dropped)."""
        if next(self._left, None) is not None:
            self._box.put(reply)

    def end(self) -> None:
        """The query is over: no more replies."""
        self._box.put(_END)

    def stream(self, deadline: float) -> Iterator[Any]:
        """The replies until the end, or until ``deadline`` (``time.monotonic()``) passes."""
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                return
            try:
                item = self._box.get(timeout=left)
            except queue.Empty:
                return
            if item is _END:
                return
            yield item
