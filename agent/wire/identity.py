"""Fleet identities (docs/design.md §8 "Trust"): who a certificate's common name says it is.

``robot-{id}``, ``world``, ``observer``, ``router``, ``render`` (the render workers of
large fleets, one key for all of them) and ``operator`` (who commands a fleet that holds
a shape to take another, docs/formation.md "Reshaping"; it never speaks for a robot); the
common name *is* the identity.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from agent.wire.fields import MAX_ROBOT_ID, ProtocolError

ROLES = ("robot", "world", "observer", "router", "render", "operator")
_ROBOT_CN = re.compile(r"robot-(0|[1-9][0-9]{0,4})")


class TrustError(ProtocolError):
    """A credential, certificate or envelope that cannot be trusted; the text says why."""


# --------------------------------------------------------------------------- identities


@dataclass(frozen=True, order=True)
class Identity:
    """Who holds a key: a ``role`` of :data:`ROLES`, and the robot id for robots."""

    role: str
    robot_id: int = -1

    def __post_init__(self) -> None:
        if self.role not in ROLES:
            raise ValueError(f"role {self.role!r} is not one of {', '.join(ROLES)}")
        if self.role == "robot":
            if isinstance(self.robot_id, bool) or not 0 <= self.robot_id <= MAX_ROBOT_ID:
                raise ValueError(f"robot id {self.robot_id!r} outside [0, {MAX_ROBOT_ID}]")
        elif self.robot_id != -1:
            raise ValueError(f"a {self.role} identity has no robot id")

    @property
    def cn(self) -> str:
        """The certificate common name: ``robot-2``, ``world``, ``observer``, ``router``,
        ``render``, ``operator``."""
        return f"robot-{self.robot_id}" if self.role == "robot" else self.role

    @classmethod
    def robot(cls, robot_id: int) -> Identity:
        return cls("robot", robot_id)

    @property
    def code(self) -> int:
        """The compact wire code of the identity: the robot id, or -1 world, -2 observer,
        -3 router, -4 render, -5 operator (one msgpack byte for the roles and robots up to 127)."""
        return self.robot_id if self.role == "robot" else -ROLES.index(self.role)

    @classmethod
    def from_code(cls, code: int) -> Identity:
        if type(code) is not int or not -len(ROLES) < code <= MAX_ROBOT_ID:
            raise TrustError(f"signer code {str(code)[:24]} names no fleet identity")
        return cls.robot(code) if code >= 0 else cls(ROLES[-code])

    @classmethod
    def parse(cls, cn: str) -> Identity:
        """The identity of a common name; :class:`TrustError` for anything else."""
        if not isinstance(cn, str) or len(cn) > 16:
            raise TrustError(f"common name {str(cn)[:32]!r} names no fleet identity")
        m = _ROBOT_CN.fullmatch(cn)
        if m:
            rid = int(m.group(1))
            if rid > MAX_ROBOT_ID:
                raise TrustError(f"common name {cn!r}: robot id outside [0, {MAX_ROBOT_ID}]")
            return cls.robot(rid)
        if cn in ROLES[1:]:
            return cls(cn)
        raise TrustError(f"common name {cn!r} names no fleet identity")
