"""The re-send timer of the agreement's repairs (agent/core/agreement.py; docs/design.md §1
step 4, §8 "Faults": re-sends are idempotent and back off).

Lost publications are repaired by re-sending; the gap between re-sends doubles from
``lo`` to ``hi`` (exponential back-off), so that a long wait costs a few sends, not a
stream. Pure: the caller passes the time.
"""

from __future__ import annotations

import math


class Backoff:
    """A re-send timer: due at once, then ``lo`` s after a send, the gap doubling up to
    ``hi`` with each send; :meth:`reset` (news) makes it due now and short again."""

    def __init__(self, lo: float, hi: float) -> None:
        self.lo, self.hi = lo, hi
        self.interval = lo
        self.next_at = -math.inf  # due at once

    def reset(self, now: float) -> None:
        self.interval = self.lo
        self.next_at = min(self.next_at, now)

    def due(self, now: float) -> bool:
        return now >= self.next_at

    def fired(self, now: float) -> None:
        self.next_at = now + self.interval
        self.interval = min(self.hi, self.interval * 2.0)
