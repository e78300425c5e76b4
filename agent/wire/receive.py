"""Receiving helpers shared by every process that listens on the bus (agents, world,
tools): :class:`Guard` keeps callbacks alive and counts what they reject, :class:`Inbox`
is the bounded queue between a callback and the thread that acts.
"""

from __future__ import annotations

import collections
import contextlib
import queue
import threading
import time
from collections.abc import Callable, Mapping
from typing import Any, Generic, TypeVar

from agent.wire.fields import ProtocolError

# --------------------------------------------------------------------------- receiving
# Shared by every process that listens on the bus (agents, world, tools): the world may
# import only this module of agent/, so the receiving helpers live here too.

#: Log lines about rejected input are cut to this many characters.
MAX_REASON = 200

T = TypeVar("T")


def reason(exc: BaseException | str, limit: int = MAX_REASON) -> str:
    """One log line about ``exc``: its text (with the type unless it is a
    ``ProtocolError``), on one line, cut to ``limit`` characters."""
    if isinstance(exc, str):
        text = exc
    else:
        try:
            msg = str(exc)
        except Exception:  # an exception whose __str__ raises: still a reason
            msg = "<unprintable>"
        text = msg if isinstance(exc, ProtocolError) else f"{type(exc).__name__}: {msg}"
    text = text[: limit * 2].replace("\n", " ").replace("\r", " ")
    return text if len(text) <= limit else text[: limit - 3] + "..."


class Guard:
    """Keeps zenoh callbacks alive: every exception is caught, counted and logged.

    :meth:`wrap` turns a callback into one that never raises; :meth:`reject` counts one
    rejected input and logs its reason (cut to ``MAX_REASON`` characters). Log lines are
    rate limited (``burst`` lines, then ``per_second``), so a flood of garbage cannot
    flood the log; the next line that is written says how many were suppressed.
    Thread-safe: zenoh calls callbacks from its own threads.
    """

    def __init__(
        self,
        log: Callable[[str], Any],
        *,
        on_reject: Callable[[], Any] | None = None,
        burst: int = 20,
        per_second: float = 2.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if burst < 1 or not per_second > 0:
            raise ValueError(f"need burst >= 1 and per_second > 0, got {burst}, {per_second}")
        self._log = log
        self._on_reject = on_reject
        self._burst = float(burst)
        self._rate = per_second
        self._clock = clock
        self._tokens = float(burst)
        self._last = clock()
        self._lock = threading.Lock()
        self.rejected = 0
        self.suppressed = 0

    def reject(self, what: str, why: BaseException | str) -> None:
        """Count one rejected input on ``what`` and log ``why`` (rate limited)."""
        with self._lock:
            self.rejected += 1
            now = self._clock()
            self._tokens = min(self._burst, self._tokens + (now - self._last) * self._rate)
            self._last = now
            if self._tokens < 1.0:
                self.suppressed += 1
                line = None
            else:
                self._tokens -= 1.0
                extra = f" (+{self.suppressed} suppressed)" if self.suppressed else ""
                self.suppressed = 0
                line = f"rejected {reason(what, 80)}: {reason(why)}{extra}"
        if self._on_reject is not None:
            with contextlib.suppress(Exception):  # a counter must not break its callback
                self._on_reject()
        if line is not None:
            with contextlib.suppress(Exception):  # nor may a broken log
                self._log(line)

    def wrap(self, fn: Callable[[T], Any], what: str) -> Callable[[T], None]:
        """``fn`` as a callback that counts and logs any exception instead of raising."""

        def guarded(arg: T) -> None:
            try:
                fn(arg)
            except Exception as exc:
                self.reject(what, exc)

        return guarded


class Inbox(Generic[T]):
    """Bounded, thread-safe queue in lanes: a full lane drops its *oldest* items.

    ``caps`` names the lanes and their capacity in items; ``max_weight`` optionally caps
    a lane's total weight too (e.g. payload bytes, so that a lane of big messages stays
    small in memory). :meth:`put` returns how many items it dropped to make room (an
    item heavier than the whole lane is itself dropped) and counts them in
    ``dropped[lane]``. :meth:`get` takes the oldest item of all lanes (arrival order),
    or with ``priority=True`` the oldest of the first non-empty lane in the order of
    ``caps``. Raises ``queue.Empty`` like ``queue.Queue``.
    """

    def __init__(
        self,
        caps: Mapping[str, int],
        priority: bool = False,
        max_weight: Mapping[str, int] | None = None,
    ) -> None:
        weights = dict(max_weight or {})
        if (
            not caps
            or any(isinstance(c, bool) or not isinstance(c, int) or c < 1 for c in caps.values())
            or any(w < 1 for w in weights.values())
            or not set(weights) <= set(caps)
        ):
            raise ValueError(
                f"every lane needs a capacity >= 1 (and weight cap >= 1), got {dict(caps)}, "
                f"{weights}"
            )
        self._lanes: dict[str, collections.deque[tuple[int, T, int]]] = {
            lane: collections.deque() for lane in caps
        }
        self._caps = dict(caps)
        self._max_weight = weights
        self._weight: collections.Counter[str] = collections.Counter()
        self._priority = priority
        self._seq = 0
        self._cond = threading.Condition()
        self.dropped: collections.Counter[str] = collections.Counter()

    def put(self, lane: str, item: T, weight: int = 0) -> int:
        """Queue ``item``; returns the number of items dropped (oldest first)."""
        with self._cond:
            q = self._lanes[lane]
            cap_w = self._max_weight.get(lane)
            if cap_w is not None and weight > cap_w:
                self.dropped[lane] += 1
                return 1
            dropped = 0
            while q and (
                len(q) >= self._caps[lane]
                or (cap_w is not None and self._weight[lane] + weight > cap_w)
            ):
                self._weight[lane] -= q.popleft()[2]
                dropped += 1
            if dropped:
                self.dropped[lane] += dropped
            q.append((self._seq, item, weight))
            self._weight[lane] += weight
            self._seq += 1
            self._cond.notify()
            return dropped

    def _pop(self) -> tuple[str, T] | None:
        best: str | None = None
        for lane, q in self._lanes.items():
            if q and (best is None or (not self._priority and q[0][0] < self._lanes[best][0][0])):
                best = lane
                if self._priority:
                    break
        if best is None:
            return None
        _, item, weight = self._lanes[best].popleft()
        self._weight[best] -= weight
        return best, item

    def get(self, timeout: float | None = None) -> tuple[str, T]:
        """The next (lane, item), waiting up to ``timeout`` s (None: forever)."""
        with self._cond:
            end = None if timeout is None else time.monotonic() + timeout
            while True:
                got = self._pop()
                if got is not None:
                    return got
                left = None if end is None else end - time.monotonic()
                if left is not None and left <= 0:
                    raise queue.Empty
                self._cond.wait(left)

    def get_nowait(self) -> tuple[str, T]:
        with self._cond:
            got = self._pop()
            if got is None:
                raise queue.Empty
            return got

    def __len__(self) -> int:
        with self._cond:
            return sum(len(q) for q in self._lanes.values())

    def lengths(self) -> dict[str, int]:
        with self._cond:
            return {lane: len(q) for lane, q in self._lanes.items()}

    def weights(self) -> dict[str, int]:
        with self._cond:
            return {lane: self._weight[lane] for lane in self._lanes}
