"""A slow world: camera and motion replies held back by a seeded random delay
(``python -m sim --reply-delay MAX_S``; docs/design.md §6 fault injection: a slow world in the chaos
soak).

The papers assume the robot's own camera and legs answer at once. A world loaded by
many robots, or a real NAO's busy NAOqi, answers late; ``tools.eval_chaos`` measures what
that does to the formation. Each reply to a camera, walk or turn query is held for a
delay drawn uniformly from ``[0, max_s]`` by a numpy ``Generator`` seeded with the
world's seed (its own stream: the world's other random draws do not change), then sent
by the world's one loop (:mod:`sim.server.server`): nothing sleeps, so the world keeps serving
every other request meanwhile. The delays are drawn in the order the replies are made.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass, field
from typing import Generic, TypeVar

import numpy as np

#: The longest delay accepted (s): an agent's camera attempt waits 15 s
#: (``agent.body.zenoh_world.CAMERA_ATTEMPT_S``); longer delays would only be timeouts.
MAX_REPLY_DELAY_S = 10.0
#: Mixed into the world's seed so that the delays are a stream of their own.
STREAM = 0x51DE1A7

Q = TypeVar("Q")
M = TypeVar("M")


def check_max_delay(max_s: float) -> float:
    """``max_s`` if it is a usable maximal delay, else a ``ValueError`` saying why."""
    if not (math.isfinite(max_s) and 0.0 <= max_s <= MAX_REPLY_DELAY_S):
        raise ValueError(f"reply delay {max_s} s must be in [0, {MAX_REPLY_DELAY_S:g}]")
    return float(max_s)


@dataclass(order=True)
class _Held(Generic[Q, M]):
    due: float
    seq: int
    query: Q = field(compare=False)
    msg: M = field(compare=False)


class DelayedReplies(Generic[Q, M]):
    """Replies waiting for their due time (monotonic seconds), earliest first."""

    def __init__(self, max_s: float, seed: int) -> None:
        self.max_s = check_max_delay(max_s)
        self._rng = np.random.default_rng([STREAM, seed & 0xFFFFFFFF])
        self._heap: list[_Held[Q, M]] = []
        self._seq = 0
        self.held = 0  # replies delayed so far

    def __len__(self) -> int:
        return len(self._heap)

    def hold(self, query: Q, msg: M, now: float) -> float:
        """Keep ``msg`` for ``query`` until ``now`` + a random delay; returns the delay."""
        delay = float(self._rng.uniform(0.0, self.max_s))
        heapq.heappush(self._heap, _Held(now + delay, self._seq, query, msg))
        self._seq += 1
        self.held += 1
        return delay

    def next_due(self) -> float | None:
        """When the earliest held reply is due (None: none held)."""
        return self._heap[0].due if self._heap else None

    def due(self, now: float) -> list[tuple[Q, M]]:
        """The replies due at ``now``, earliest first (taken out)."""
        out = []
        while self._heap and self._heap[0].due <= now:
            h = heapq.heappop(self._heap)
            out.append((h.query, h.msg))
        return out

    def take_all(self) -> list[tuple[Q, M]]:
        """Every held reply, earliest first (the world shuts down: they go out now)."""
        out = [(h.query, h.msg) for h in sorted(self._heap)]
        self._heap.clear()
        return out
