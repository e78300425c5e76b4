"""Who drives which robot of the world: claims, live agents and session binding (docs/design.md
§3 ``world/register``, §8 "The world obeys robot i's key alone for robot i").

- **Claims** (``world/register``, for ``--id auto``): a request gets the lowest free robot
  id of the scenario, or the id it wants if that one is free. An id is taken while it is
  claimed or while an agent holds its liveliness token ``nao/alive/{id}`` (agents started
  with a fixed ``--id`` register nothing but hold the token); a claim is released when
  that token goes away.
- **Binding** (secure worlds): a robot's key claims only its own robot, and only robot
  i's key drives robot i, in the session (epoch) bound to it: the one that claimed it,
  or, with a fixed id, the one that last commanded it. A newer epoch of the same key (a
  restarted agent) takes an unclaimed robot over; an older one (a replay) is refused.

Only the world loop of :mod:`sim.server.server` calls these methods; they keep no other state.
"""

from __future__ import annotations

from agent.wire import trust


class Unauthorised(ValueError):
    """A command the sender's key may not give (counted as untrusted by the world)."""


class RobotBindings:
    """Claimed robots, robots with a live agent token, and the session bound to each."""

    def __init__(self, robot_ids: tuple[int, ...]) -> None:
        self.robot_ids = robot_ids  # the scenario's robots, in order
        self.claims: set[int] = set()
        self.alive: set[int] = set()  # ids with a live agent token (nao/alive/{id})
        self.bound: dict[int, int] = {}  # robot id -> the epoch of the session driving it

    def token(self, rid: int, gone: bool) -> bool:
        """An agent's liveliness token for ``rid`` came or went; True when that released
        a claim."""
        if not gone:
            self.alive.add(rid)
            return False
        self.alive.discard(rid)
        if rid in self.claims:
            self.claims.discard(rid)
            return True
        return False

    def authorise(self, who: trust.Identity | None, epoch: int, rid: int) -> None:
        """Secure: only robot ``rid``'s key, in the session bound to ``rid``, drives it;
        :class:`Unauthorised` otherwise. The session becomes the one bound to ``rid``."""
        if who != trust.Identity.robot(rid):
            raise Unauthorised(f"{who.cn if who else 'nobody'} may not command robot {rid}")
        bound = self.bound.get(rid)
        if bound is not None and epoch != bound and (rid in self.claims or epoch < bound):
            raise Unauthorised(f"robot {rid} is bound to another session of its key")
        self.bound[rid] = epoch

    def register(self, who: trust.Identity | None, epoch: int, want: int) -> int:
        """Claim a robot for a ``RegisterRequest(want)`` (``want`` -1: any free one) and
        return its id, or a ``ValueError`` saying why not. ``who`` (secure worlds): the
        request's signer, who may claim its own robot id and only that one."""
        if who is not None:
            if who.role != "robot":
                raise ValueError(f"{who.cn} is not a robot and may not claim one")
            if want not in (-1, who.robot_id):
                raise ValueError(f"{who.cn} may not claim robot {want}")
            want = who.robot_id
        taken = self.claims | self.alive
        free = [r for r in self.robot_ids if r not in taken]
        if want >= 0:
            if want not in self.robot_ids:
                raise ValueError(f"robot {want} is not in this world's scenario")
            if want in self.claims:
                raise ValueError(f"robot {want} is already claimed")
            if want in self.alive:
                raise ValueError(f"robot {want} is already driven by a live agent")
            rid = want
        elif not free:
            raise ValueError(f"every robot is claimed ({list(self.robot_ids)})")
        else:
            rid = free[0]
        self.claims.add(rid)
        if who is not None:
            self.bound[rid] = epoch  # the claiming session drives it from now on
        return rid
