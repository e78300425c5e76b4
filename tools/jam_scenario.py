"""A jam for good (a dense fleet must repair its plan or stop honestly; the CI test
``tests/system/test_dense_jam.py``): a NAO that runs no agent stands on a slot of the fleet's plan.

The fleet's plan keeps every path clear of every robot it knows (NAO paper 4.2; the
safety rule of agent/core/formation/waves/safety.py), so its members never jam one another for
good. A NAO that is not a member (switched off, or fallen) is seen but never identified
(Algorithm 2 leaves a one-sided detection unidentified), so the plan may put a slot on
it: the robot of that slot waits at the corridor check (agent/core/control/corridor.py)
and cannot reach it, whatever it does. The fleet must then stop honestly, with one
reason on every agent (agent/core/formation/waves/jam.py), and never report the formation
with its hole as held.

:func:`jam_scenario` plans the pyramid from the ground-truth starts of ``generate(n,
seed)`` with the formation core and puts the bystander (id ``n + 1``) on the target of
the robot of the latest wave (the longest path first) that keeps ``START_GAP`` from every
start; derived seeds when none does. Deterministic for a given (n, seed, d_e, φ_e).

    python -m tools.jam_scenario --robots 4 --seed 3 --out out/jam.json
"""

from __future__ import annotations

import argparse
import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from agent.core.formation.params import D_E, PHI_E_DEG, PlanParams
from agent.core.formation.plan import plan_from_positions
from sim.scenarios import RobotSpec, Scenario, dump, generate

#: m from the bystander to every start: the searching robots see it whole (0.5 m is the
#: detector's near limit) and the plan's paths have room to pass it
START_GAP = 0.6
SEED_STRIDE = 7919  # derived seeds, as tools/lib/obstacle_scenario.py
MAX_TRIES = 50


def bystander_spot(
    plan_robots: list[tuple[int, int, float, np.ndarray]], starts: np.ndarray
) -> int:
    """Index into ``plan_robots`` = [(wave, robot id, path length, target), ...] of the
    robot whose target the bystander takes: the latest wave, then the longest path, then
    the lowest id, among those whose target keeps ``START_GAP`` from every start; -1."""
    order = sorted(
        range(len(plan_robots)),
        key=lambda k: (-plan_robots[k][0], -plan_robots[k][2], plan_robots[k][1]),
    )
    for k in order:
        target = plan_robots[k][3]
        if float(np.min(np.hypot(*(starts - target).T))) >= START_GAP:
            return k
    return -1


def jam_scenario(
    n: int, seed: int, d_e: float = D_E, phi_e: float = math.radians(PHI_E_DEG)
) -> tuple[Scenario, int]:
    """(the scenario, the id of the robot whose slot the bystander takes); the bystander's
    id is ``n + 1``. The scenario keeps ``seed`` for its textures and noise; ``ValueError``
    after ``MAX_TRIES`` derived seeds."""
    if n < 2:
        raise ValueError(f"a jam needs a fleet of >= 2 robots, got {n}")
    for j in range(MAX_TRIES):
        sc = generate(n, seed + SEED_STRIDE * j)
        robots = sorted(sc.robots, key=lambda r: r.id)
        pos = np.array([[r.x, r.y] for r in robots])
        plan = plan_from_positions([r.id for r in robots], pos, PlanParams(d_e=d_e, phi_e=phi_e))
        rows = [
            (int(rp.wave), int(rp.robot_id), rp.length(), np.asarray(rp.target))
            for rp in plan.robots
        ]
        k = bystander_spot(rows, pos)
        if k < 0:
            continue
        x, y = (round(float(v), 3) for v in rows[k][3])
        if max(abs(x), abs(y)) > sc.room - 0.5:
            continue
        bystander = RobotSpec(n + 1, x, y, math.pi / 2)
        return replace(sc, seed=seed, robots=(*sc.robots, bystander)), rows[k][1]
    raise ValueError(f"no scenario of {MAX_TRIES} seeds leaves room for a bystander on a slot")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n", 1)[0])
    p.add_argument(
        "--robots", type=int, default=4, help="fleet members (the bystander is one more)"
    )
    p.add_argument("--seed", type=int, default=3)
    p.add_argument("--d-e", type=float, default=D_E)
    p.add_argument("--phi-e-deg", type=float, default=PHI_E_DEG)
    p.add_argument("--out", type=Path, required=True)
    a = p.parse_args(argv)
    sc, victim = jam_scenario(a.robots, a.seed, a.d_e, math.radians(a.phi_e_deg))
    dump(sc, a.out)
    print(
        f"{a.out}: robots 1..{a.robots} run agents; NAO {a.robots + 1} stands on the slot of robot {victim}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
