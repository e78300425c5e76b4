"""A shape: a built-in rule (:mod:`builtin`) or a fixed tree of slots from a formation file
(:mod:`schema`), its slots for a fleet of n, and its digest (docs/formation.md
"Shapes"; the pyramid of AUV paper II is the default).

The digest is sha256 over a canonical binary form: a version tag, the rule, the
orientation, then per slot of a fixed tree its parent (int64), distance and angle
(float64, little-endian). The name is not part of it: two files that define the same
tree plan the same formation. The plan's digest covers the shape's (:mod:`plan`), and so
does the agreed-parameters digest of every agent: agents told different shapes never
agree on a plan.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np

from agent.core.formation.shape.builtin import NAMES, ORIENT, RULES
from agent.core.formation.shape.tree import Slots, check_tree, compose

#: How the fleet's principal axis lies on the shape (see :mod:`builtin`).
ORIENTS = ("depth", "width")
#: The rule of a formation file's fixed tree.
TREE = "tree"


@dataclass(frozen=True)
class Shape:
    """A formation's shape. ``rule``: one of :data:`builtin.NAMES` (scales with N) or
    :data:`TREE` (``edges``: per slot 1..K its (parent, distance m, angle rad), see
    :mod:`tree`; a fleet of n <= K + 1 takes slots 0..n−1)."""

    name: str = "pyramid"
    rule: str = "pyramid"
    edges: tuple[tuple[int, float, float], ...] = ()
    orient: str = "depth"
    #: where it came from: a built-in's name or a formation file's path (not in the
    #: digest: what ``--shape`` is given again to load it)
    source: str = field(default="", compare=False)
    digest: str = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"a shape needs a name, got {self.name!r}")
        if self.rule not in (*NAMES, TREE):
            raise ValueError(f"shape rule must be one of {(*NAMES, TREE)}, got {self.rule!r}")
        if self.orient not in ORIENTS:
            raise ValueError(f"shape orient must be one of {ORIENTS}, got {self.orient!r}")
        if self.rule == TREE:
            if not self.edges:
                raise ValueError("a tree shape needs at least one child slot")
            check_tree(*self._arrays())
        elif self.edges:
            raise ValueError(f"the built-in shape {self.rule!r} takes no slots")
        object.__setattr__(self, "digest", self._digest())
        if not self.source and self.rule != TREE:
            object.__setattr__(self, "source", self.rule)

    def _arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        parent = np.array([-1, *(e[0] for e in self.edges)], dtype=np.int64)
        distance = np.array([0.0, *(e[1] for e in self.edges)], dtype=np.float64)
        angle = np.array([0.0, *(e[2] for e in self.edges)], dtype=np.float64)
        return parent, distance, angle

    def _digest(self) -> str:
        h = hashlib.sha256(b"nao-formation/shape/v1")
        h.update(f"{self.rule}/{self.orient}/".encode())
        parent, distance, angle = self._arrays()
        h.update(parent[1:].astype("<i8").tobytes())
        h.update(distance[1:].astype("<f8").tobytes())
        h.update(angle[1:].astype("<f8").tobytes())
        return h.hexdigest()

    @property
    def capacity(self) -> int | None:
        """The most robots the shape holds (None: a built-in, any N)."""
        return len(self.edges) + 1 if self.rule == TREE else None

    @property
    def nested(self) -> bool:
        """Whether the slots of n robots are the first n slots of every larger fleet's
        (every shape but ``circle`` and ``grid``, whose layout depends on N)."""
        return self.rule not in ("circle", "grid")

    def check_fleet(self, n: int) -> None:
        """``ValueError`` when a fleet of ``n`` robots does not fit the shape: a fixed tree
        with fewer slots than robots (a built-in holds any N; a fleet of N takes slots
        0..N−1). One message naming the shape, its file and both counts; checked where the
        fleet size is first known (the agent's ``--fleet-size``, a fleet's spec), so that a
        short file stops the start, not the plan."""
        cap = self.capacity
        if cap is not None and n > cap:
            where = f" (file {self.source})" if self.source else ""
            raise ValueError(
                f"shape {self.name!r}{where} has {cap} slots, too few for {n} robots "
                f"(a fleet of N robots takes its first N slots)"
            )

    def slots(self, n: int, d_e: float, phi_e: float) -> Slots:
        """The slots of a fleet of ``n`` (``ValueError`` for n < 1, a bad d_e or φ_e, or
        more robots than a fixed tree holds)."""
        if self.rule != TREE:
            return RULES[self.rule](n, d_e, phi_e)
        if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
            raise ValueError(f"number of robots must be an int >= 1, got {n!r}")
        self.check_fleet(int(n))
        parent, distance, angle = (a[: int(n)] for a in self._arrays())
        return Slots(parent, distance, angle, compose(parent, distance, angle))

    def text(self) -> str:
        """``line (3f2a9c1b0d4e)``: the name and the digest's first 12 hex digits."""
        return f"{self.name} ({self.digest[:12]})"


#: The built-in shapes by name.
BUILTIN = {name: Shape(name, name, (), ORIENT[name]) for name in NAMES}
#: The default shape: the papers' pyramid.
PYRAMID = BUILTIN["pyramid"]
