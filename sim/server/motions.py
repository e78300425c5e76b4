"""The world's walks and turns in flight, and motion request ids (docs/design.md §8 "motion
commands carry ids so a retry never walks twice"; docs/faults.md: lost replies on a lossy radio).

A robot runs one motion at a time: a second one while it moves is refused as busy. A
``WalkRequest`` / ``TurnRequest`` with a ``request_id`` (> 0) is executed once per
(robot, id): a repeat while it runs waits for the same motion, a repeat after it is
answered with the first result (the last ``cache`` results per robot are kept, oldest
dropped), and an id reused for the other kind of motion is refused. So a client may
retry a motion whose reply it lost.

Only the world loop of :mod:`sim.server.server` calls these methods; ``start`` is its own
callable, run at once on that loop.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field

from agent.wire import CommandReply
from sim.physics.locomotion import Done
from sim.server.requests import Request


@dataclass
class Pending:
    """A motion in flight: the request that started it and the repeats waiting for it."""

    query: Request
    kind: str
    robot_id: int
    request_id: int = 0
    waiters: list[Request] = field(default_factory=list)  # repeats of request_id


class Motions:
    """The motions in flight, by robot, and the first results of request ids."""

    def __init__(self, cache: int) -> None:
        if cache < 1:
            raise ValueError(f"motion cache {cache} must be >= 1")
        self.cache = cache
        self.pending: dict[int, Pending] = {}
        # robot -> request id -> (kind, first result), at most ``cache`` per robot
        self.results: dict[int, OrderedDict[int, tuple[str, CommandReply]]] = {}
        self.repeats = 0  # motion requests answered without executing them again

    def request(
        self,
        q: Request,
        rid: int,
        kind: str,
        request_id: int,
        busy: bool,
        start: Callable[[], None],
    ) -> CommandReply | None:
        """A ``kind`` motion of robot ``rid`` asked by ``q``: a repeat of ``request_id``
        is answered with the first result (returned, to be sent now) or waits for the
        running motion (None); anything else starts (``start()``, None), unless the robot
        is ``busy`` or moving (``ValueError``)."""
        if request_id:
            done = self.results.get(rid, OrderedDict()).get(request_id)
            p = self.pending.get(rid)
            first = (
                done[0] if done is not None else p.kind if p and p.request_id == request_id else ""
            )
            if first and first != kind:
                raise ValueError(
                    f"request id {request_id} of robot {rid} was a {first}, not a {kind}"
                )
            if done is not None:
                self.repeats += 1
                return done[1]
            if p is not None and p.request_id == request_id:
                self.repeats += 1
                p.waiters.append(q)  # answered with the running motion's result
                return None
        if rid in self.pending or busy:
            raise ValueError(f"robot {rid} is busy with a motion")
        start()
        self.pending[rid] = Pending(q, kind, rid, request_id)
        return None

    def finish(self, d: Done) -> tuple[list[Request], CommandReply] | None:
        """The motion of ``d.robot_id`` ended: the requests to answer and their reply
        (None if no request started it)."""
        p = self.pending.pop(d.robot_id, None)
        if p is None:
            return None
        rep = CommandReply(robot_id=d.robot_id, status=d.status, t_sim=d.t_sim, detail=d.detail)
        if p.request_id:
            cache = self.results.setdefault(d.robot_id, OrderedDict())
            cache[p.request_id] = (p.kind, rep)
            while len(cache) > self.cache:
                cache.popitem(last=False)
        return [p.query, *p.waiters], rep

    def abandon(self) -> list[Request]:
        """Every request still waiting for a motion (the world is shutting down)."""
        out = [q for p in self.pending.values() for q in (p.query, *p.waiters)]
        self.pending.clear()
        return out
