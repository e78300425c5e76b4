"""The operator's reshape command (docs/formation.md "Reshaping", docs/design.md §3 and §8).

Once the fleet holds a shape, the ``operator`` identity (never a robot: the router's
access control lets only it publish on :data:`~agent.wire.keys.KEY_RESHAPE`, and every
agent checks the signature's owner, :func:`agent.net.bus.key_owner`) publishes one
:class:`ReshapeMsg`: the plan the fleet holds (``base``, the digest every robot shows
in its status) and the new shape, in the fields of
:class:`agent.core.formation.shape.spec.Shape` and with its digest. Checked here: every
field's type and bound, a built-in rule without slots, a tree whose every slot's parent
is an earlier slot. The agent checks the rest against the core (the rule is one it
knows, the shape's digest is the one given, the fleet fits it) and refuses the command
with the reason otherwise.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

from agent.wire.fields import (
    MAX_SHAPE_SLOTS,
    ProtocolError,
    _float,
    _hex,
    _int,
    _seq,
    _str,
    _tuple,
)
from agent.wire.messages import Message

#: The rule of a shape given slot by slot (``agent.core.formation.shape.spec.TREE``; the
#: wire names it without importing the core).
TREE_RULE = "tree"
#: The longest shape name a command carries.
MAX_SHAPE_NAME = 64
#: Largest distance from a slot to its parent (m), the widest angle (rad, a turn and more)
MAX_SLOT_DISTANCE = 100.0
MAX_SLOT_ANGLE = 10.0
#: A rule or an orientation: a short lowercase word.
_WORD = re.compile(r"[a-z][a-z0-9_-]{0,15}", re.ASCII)


def _word(name: str) -> Callable[[Any], str]:
    text = _str(name, 16)

    def check(v: Any) -> str:
        w = text(v)
        if not _WORD.fullmatch(w):
            raise ProtocolError(f"{name}: {w!r} is not a lowercase word of at most 16 characters")
        return w

    return check


_SLOT = _tuple(
    "slot",
    _int("slot parent", 0, MAX_SHAPE_SLOTS),
    _float("slot distance", 0.0, MAX_SLOT_DISTANCE),
    _float("slot angle", -MAX_SLOT_ANGLE, MAX_SLOT_ANGLE),
)


@dataclass(frozen=True)
class ReshapeMsg(Message):
    """Take the shape of these fields, from the plan ``base`` the fleet holds.

    ``command``: the operator's number of this command (a retry repeats it, so an agent
    acts on it once); ``base``: the digest of the plan the fleet holds (an agent holding
    another refuses the command: every agent must plan the same transition);
    ``name``, ``rule``, ``orient``, ``slots`` and ``shape_digest``: the new shape
    (``slots``: per child slot (parent slot, distance m, angle rad), empty for a built-in
    rule).
    """

    TAG: ClassVar[str] = "reshape"
    command: int
    base: str
    name: str
    rule: str
    orient: str
    shape_digest: str
    slots: tuple[tuple[int, float, float], ...] = ()
    SCHEMA: ClassVar[Mapping[str, Callable[[Any], Any]]] = {
        "command": _int("command", 1, 2**31 - 1),
        "base": _hex("base"),
        "name": _str("name", MAX_SHAPE_NAME),
        "rule": _word("rule"),
        "orient": _word("orient"),
        "shape_digest": _hex("shape_digest"),
        "slots": _seq("slots", _SLOT, MAX_SHAPE_SLOTS),
    }

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.name:
            raise ProtocolError("name: a shape needs a name")
        if self.rule == TREE_RULE and not self.slots:
            raise ProtocolError("slots: a tree shape needs at least one child slot")
        if self.rule != TREE_RULE and self.slots:
            raise ProtocolError(f"slots: the built-in rule {self.rule!r} takes none")
        for k, (parent, _, _) in enumerate(self.slots):
            if parent > k:  # slots[k] is slot k + 1: its parent is one of 0..k
                raise ProtocolError(f"slots[{k}]: parent {parent} is not an earlier slot (0..{k})")
