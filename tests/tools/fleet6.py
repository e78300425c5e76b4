"""A fleet of six as an observer sees it, made up for the tests of the plan's drawing
(tools/harness/view/scene.py, tools/web/view.js): ideal records of aligned starts, the
ground truth, and statuses that report the digests of the plans the fleet agreed."""

from __future__ import annotations

import math
from typing import Any

from agent.adapters import FormationAdapter
from agent.core.formation.params import PlanParams
from agent.core.formation.plan import Plan
from agent.wire import NeighborRecordMsg, StatusMsg, TruthPosesMsg
from tools.harness.view.scene import to_world

NORTH = math.pi / 2
#: the starts (world m), every robot facing north, far enough apart for every built-in shape
WORLD = {
    1: (0.0, 0.0),
    2: (1.2, 0.3),
    3: (-1.1, 0.4),
    4: (0.2, 1.3),
    5: (-0.3, -1.2),
    6: (1.3, -1.0),
}


def ideal_records(
    world: dict[int, tuple[float, float]],
) -> tuple[NeighborRecordMsg, ...]:
    """Ideal records of an aligned fleet standing at ``world`` (m): each robot sees every
    other where it stands."""
    return tuple(
        NeighborRecordMsg(
            sender=i,
            round=0,
            neighbours=tuple((wx - x, wy - y) for j, (wx, wy) in world.items() if j != i),
        )
        for i, (x, y) in world.items()
    )


def records() -> tuple[NeighborRecordMsg, ...]:
    """The six's records (the common frame is robot 1's)."""
    return ideal_records(WORLD)


def plan(params: PlanParams) -> Plan:
    return FormationAdapter().plan(records(), params)


def truth(t: float, dx: float = 0.0) -> TruthPosesMsg:
    return TruthPosesMsg(
        t_sim=t, poses=tuple((i, x + dx, y, NORTH) for i, (x, y) in sorted(WORLD.items()))
    )


def run(*digests: str) -> list[tuple[str, Any]]:
    """Truth, the records, then per digest (one plan after another) every robot's status
    in ``move`` reporting it, the robots a step further each time."""
    out: list[tuple[str, Any]] = [("world/truth/poses", truth(0.5))]
    out += [(f"nao/{r.sender}/record", r) for r in records()]
    for k, digest in enumerate(digests):
        out.append(("world/truth/poses", truth(1.0 + k, dx=0.05 * k)))
        for i in WORLD:
            st = StatusMsg(sender=i, phase="move", wave=0, plan_digest=digest, detail="leg 1")
            out.append((f"nao/{i}/status", st))
    out.append(("world/truth/poses", truth(1.0 + len(digests), dx=0.1)))
    return out


def targets(p: Plan, frame_plan: Plan | None = None) -> dict[int, tuple[float, float]]:
    """Each robot's target in the world (the common frame is robot 1's start pose, the
    frame robot of ``frame_plan``, default ``p``)."""
    fr = int((frame_plan or p).frame_robot)
    frame = (*WORLD[fr], NORTH)
    return {int(rp.robot_id): to_world(rp.target, frame) for rp in p.robots}
