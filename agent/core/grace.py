"""Membership grace on a lossy radio (docs/design.md §8 "Faults").

A live member's liveliness token can vanish for a while (its zenoh lease expires, its
client reconnects and declares the token again). :class:`Grace` turns token changes and
the member's own publications into membership: a vanished token counts as gone only
after ``grace`` seconds in which nothing (record, digest or status) was heard from that
member; a token that comes back, or any publication, ends the count. The caller feeds
:meth:`agent.core.agreement.Agreement.member_left` only with what :meth:`Grace.expired`
returns.
"""

from __future__ import annotations

import math


class Grace:
    """When a member whose liveliness token vanished counts as gone (module docstring).

    Pure: the caller passes the time. ``grace`` 0 makes a vanished token count as gone
    at the next :meth:`expired`.
    """

    def __init__(self, grace: float) -> None:
        if not (math.isfinite(grace) and grace >= 0.0):
            raise ValueError(f"grace must be finite and >= 0, got {grace}")
        self.grace = grace
        self._vanished: dict[int, float] = {}  # member -> when last its token or a message was seen

    def token(self, robot_id: int, present: bool, now: float) -> None:
        """The member's liveliness token appeared (``present``) or vanished."""
        if present:
            self._vanished.pop(robot_id, None)
        else:
            self._vanished.setdefault(robot_id, now)

    def heard(self, robot_id: int, now: float) -> None:
        """A record, digest or status of the member arrived: a heartbeat."""
        if robot_id in self._vanished:
            self._vanished[robot_id] = max(self._vanished[robot_id], now)

    def pending(self) -> tuple[int, ...]:
        """Members whose token is gone but whose grace has not run out, sorted."""
        return tuple(sorted(self._vanished))

    def next_expiry(self) -> float:
        """When the first pending member counts as gone, if nothing is heard of it
        (``math.inf``: nobody pending): a waiting caller wakes then to :meth:`expired`."""
        return min(self._vanished.values(), default=math.inf) + self.grace

    def expired(self, now: float) -> list[int]:
        """Members gone for good at ``now`` (sorted); they are forgotten here."""
        out = sorted(i for i, t in self._vanished.items() if now - t >= self.grace)
        for i in out:
            del self._vanished[i]
        return out
