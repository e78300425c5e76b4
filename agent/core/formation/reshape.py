"""Reshaping on command: the plan from the shape a fleet holds to another (docs/formation.md
"Reshaping", docs/design.md §11; the same planner as every plan, NAO paper 4.2 and
5.2.2 (iii), AUV paper III.B–C for the slots). The circle pattern's second plan, from
its circle to the formation (AUV III.B.2.a), is such a transition (:func:`from_circle`).

The fleet holds the plan every agent agreed on; an operator's command names that plan
(its digest) and the new shape. Every agent plans the transition from data all of them
hold bit for bit, and nothing else: the held plan's targets (the slots, in the common
frame), its ids, its obstacles (with the robots it left out, which stand still) and
the agreed parameters with the new shape. The transition is then one more plan of
:func:`~agent.core.formation.plan.plan_from_positions`, from those slots as starts:
the same assignment (timing-robust, Lemma 1 strengthened), the 2r clearance rule,
waves with release points, the banded plan when nothing else is safe. The shape's frame
follows the held slots (their mean and principal axis, ``PlanParams.orientation``),
so the new formation stands where the old one stood.

What each robot's own check corrected (its ``shift`` after it arrived, a few cm) is
not used: it is known to that robot alone unless exchanged and agreed, and the plan
would then wait for one more agreement round. A robot walks from where it believes it
stands to its new target (its legs are goals, not vectors), its steps are checked by its
camera (agent/phases/safe_steps.py), and at the new slot it checks and corrects against
its new parent as at every hold (docs/design.md §11 gives the reasons).

The transition's digest chains the held plan's and the new plan's, so a fleet that
took line then wedge never shows the digest of one that took the wedge at once. ψ (each
robot's start heading in the common frame) and the robots left out carry over.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from agent.core.formation.params import PlanParams
from agent.core.formation.plan import Plan, plan_from_positions
from agent.core.formation.shape.spec import TREE, Shape


def command_shape(
    name: str,
    rule: str,
    orient: str,
    slots: Sequence[tuple[int, float, float]],
    digest: str,
) -> Shape:
    """The shape an operator's command describes (its fields, as :class:`Shape` takes
    them); ``ValueError`` when they make no shape, or another shape than ``digest``."""
    shape = Shape(
        name=name,
        rule=rule,
        edges=tuple((int(p), float(d), float(a)) for p, d, a in slots) if rule == TREE else (),
        orient=orient,
        source=name if rule != TREE else "",
    )
    if rule != TREE and slots:
        raise ValueError(f"the built-in shape {rule!r} takes no slots")
    if shape.digest != digest:
        raise ValueError(
            f"shape {name!r}: its fields make digest {shape.digest[:12]}, the command says "
            f"{digest[:12]}"
        )
    return shape


def transition_plan(
    held: Plan, shape: Shape, params: PlanParams, anchor: int | None = None
) -> Plan:
    """The plan from the slots of ``held`` (the common frame) to ``shape`` with the
    agreed ``params`` (module docstring). The robots of ``held`` may come in any order.
    ``anchor``: a robot that takes the new shape's slot 0 where it stands
    (:func:`~agent.core.formation.plan.plan_from_positions`).

    Raises ``ValueError`` for a held plan without robots, a fleet the shape cannot hold,
    slots of the shape closer than two robots, or no safe plan (obstacles only, or
    with the anchor in place)."""
    if not held.robots:
        raise ValueError("the held plan has no robots")
    robots = sorted(held.robots, key=lambda r: r.robot_id)
    ids = [int(r.robot_id) for r in robots]
    shape.check_fleet(len(ids))
    wanted = replace(params, shape=shape)  # checks the new slots' spacing
    targets = np.array([r.target for r in robots], dtype=np.float64).reshape(-1, 2)
    obstacles = np.asarray(held.obstacles, dtype=np.float64).reshape(-1, 2)
    plan = plan_from_positions(
        ids,
        targets,
        wanted,
        obstacles if len(obstacles) else None,
        frame_robot=held.frame_robot,
        anchor=anchor,
    )
    psi = np.asarray(held.psi, dtype=np.float64)
    if len(psi):  # ψ in the robots' order: by id, as the plan's
        order = {int(r.robot_id): k for k, r in enumerate(held.robots)}
        psi = np.array([psi[order[i]] for i in ids], dtype=np.float64)
    h = hashlib.sha256(b"nao-formation/reshape/v1")
    h.update(held.digest.encode())
    h.update(plan.digest.encode())
    h.update(np.ascontiguousarray(psi, dtype="<f8").tobytes())
    h.update(repr((held.excluded, held.verdict)).encode())
    return replace(
        plan, psi=psi, excluded=held.excluded, verdict=held.verdict, digest=h.hexdigest()
    )


def circle_leader(circle: Plan) -> int:
    """The robot at 90° of the common frame on the circle pattern's circle: the one on
    slot 1, straight ahead of the centre (:mod:`~agent.core.formation.shape.circle_pattern`);
    the centre itself in a fleet of one."""
    on_slot_1 = [int(r.robot_id) for r in circle.robots if int(r.order) == 1]
    return on_slot_1[0] if on_slot_1 else int(circle.leader)


def from_circle(circle: Plan, params: PlanParams) -> Plan:
    """The circle pattern's second plan (AUV III.B.2.a): from the circle ``circle`` (the
    plan of ``plan_from_records`` with the orientation ``cp``) to the formation of
    ``params.shape``, facing north, with the robot at 90° (:func:`circle_leader`) as its
    leader where it stands; the digest chains the circle's, as every transition's."""
    if params.orientation != "cp":
        raise ValueError(f"the circle pattern's orientation is 'cp', got {params.orientation!r}")
    return transition_plan(circle, params.shape, params, anchor=circle_leader(circle))
