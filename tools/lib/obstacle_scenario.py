"""Scenarios with obstacles in the way (NAO paper 5.1.2; ``tools.demo --obstacles K``).

Also the demo's obstacle numbers (:func:`judge_obstacles`) and drawing
(:func:`draw_obstacles`), so that the harness (``tools/harness``) only calls them.

:func:`sim.scenarios.generate` keeps its obstacles 0.8 m from every robot, so they rarely
stand on anybody's way. :func:`blocking_scenario` instead plans the pyramid from the
ground-truth starts with the formation core (no obstacles) and puts each obstacle on a
straight path of that plan: the longest paths first, at the first of the fractions
``FRACTIONS`` of the path that keeps ``START_GAP`` from every start and ``OBSTACLE_GAP``
from the obstacles already placed. Deterministic for a given (n, seed, k, d_e, φ_e).
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from agent.core.formation.params import PlanParams
from agent.core.formation.plan import plan_from_positions
from agent.core.nao import OBSTACLE_RADIUS, OBSTACLE_RGBA
from sim.physics.nao_model import FOOTPRINT_RADIUS
from sim.scenarios import ObstacleSpec, Scenario, dump, generate

OBSTACLE_COLOUR = OBSTACLE_RGBA[:3]
CONTACT_SLACK = 0.005  # m: a footprint gap this small is a contact (the world stops it)

#: Where on a path an obstacle may stand, tried in turn (0 = start, 1 = target).
FRACTIONS = (0.5, 0.6, 0.4, 0.7, 0.8, 0.3, 0.9, 1.0)
#: Obstacle centre to any robot start (m): room for the planner's clearance (2·radius).
START_GAP = 0.5
OBSTACLE_GAP = 0.6  # m between obstacle centres
SEED_STRIDE = 7919  # derived seeds (a prime: they do not meet the next runs' seeds)
MAX_TRIES = 50
#: The plan moves the pattern out of the obstacles (the default "near" placement by
#: 0.4-1.6 m in the 6-robot, 3-obstacle demos; the paper's sideways shift by 2-3 m), and
#: the agents know no walls: the room's half-size grows by this much (m) over the
#: generated one.
ROOM_EXTRA = 1.5


def blocking_points(
    starts: np.ndarray, targets: np.ndarray, k: int, room: float
) -> list[tuple[float, float]]:
    """``k`` obstacle centres on the straight paths ``starts`` → ``targets`` (world m)."""
    lengths = np.hypot(*(targets - starts).T)
    placed: list[tuple[float, float]] = []
    for row in np.argsort(-lengths, kind="stable"):
        if len(placed) == k:
            break
        for f in FRACTIONS:
            p = starts[row] + f * (targets[row] - starts[row])
            if max(abs(p[0]), abs(p[1])) > room - 0.5:
                continue
            if np.min(np.hypot(*(starts - p).T)) < START_GAP:
                continue
            if any(math.hypot(p[0] - q[0], p[1] - q[1]) < OBSTACLE_GAP for q in placed):
                continue
            placed.append((round(float(p[0]), 3), round(float(p[1]), 3)))
            break
    if len(placed) < k:
        raise ValueError(f"only {len(placed)} of {k} obstacles fit on the paths")
    return placed


def blocking_scenario(n: int, seed: int, k: int, d_e: float, phi_e: float) -> Scenario:
    """A generated scenario with ``k`` obstacles on the straight paths of its plan.

    The seed's own scenario when its paths leave room for ``k`` obstacles; else the
    first of the derived seeds ``seed + SEED_STRIDE·j`` (j = 1, 2, ...) whose paths do
    (dense fleets have short paths). The scenario keeps ``seed`` for its textures and
    noise; ``ValueError`` after ``MAX_TRIES`` seeds.
    """
    if k < 1:
        raise ValueError(f"obstacle count must be >= 1, got {k}")
    last = ""
    for j in range(MAX_TRIES):
        sc = generate(n, seed + SEED_STRIDE * j)
        robots = sorted(sc.robots, key=lambda r: r.id)
        pos = np.array([[r.x, r.y] for r in robots])
        plan = plan_from_positions([r.id for r in robots], pos, PlanParams(d_e=d_e, phi_e=phi_e))
        targets = np.array([plan.robot(r.id).target for r in robots])
        try:
            pts = blocking_points(pos, targets, k, sc.room)
        except ValueError as exc:
            last = str(exc)
            continue
        obstacles = tuple(ObstacleSpec(x, y) for x, y in pts)
        return replace(sc, seed=seed, obstacles=obstacles, room=sc.room + ROOM_EXTRA)
    raise ValueError(f"no scenario of {MAX_TRIES} seeds takes {k} obstacles ({last})")


def obstacle_world_args(
    n: int, seed: int, k: int, d_e: float, phi_e: float, out: Path, result: dict[str, Any]
) -> list[str]:
    """World flags for ``tools.demo --obstacles K``: the blocking scenario, written to
    ``out/scenario.json``; ``result["obstacles"]`` gets [x, y, radius] per obstacle."""
    sc = blocking_scenario(n, seed, k, d_e, phi_e)
    path = out / "scenario.json"
    dump(sc, path)
    result["obstacles"] = [[o.x, o.y, o.radius] for o in sc.obstacles]
    return ["--scenario", str(path)]


def judge_obstacles(
    result: dict[str, Any],
    truth: list[tuple[float, dict[int, tuple[float, float, float]]]],
    contacts: list[tuple[float, int, int]],
    plan: Any,
) -> None:
    """Obstacle numbers of a demo run into ``result``: contacts with obstacles (robot and
    obstacle footprints touching in the recorded truth, each pair once; the world's own
    b = -1 contacts count walls too: ``wall_or_obstacle_contacts``), the smallest gap (m)
    between a robot's footprint and an obstacle, and the obstacles the fleet planned
    around (perceived, merged; world frame) with their position errors."""
    obs = np.array(result.get("obstacles", []), dtype=np.float64).reshape(-1, 3)
    result["wall_or_obstacle_contacts"] = sum(1 for c in contacts if c[2] < 0)
    gap = math.inf
    touching: set[tuple[int, int]] = set()
    for _, poses in truth:
        for rid, (x, y, _h) in poses.items():
            if obs.size:
                d = np.hypot(obs[:, 0] - x, obs[:, 1] - y) - obs[:, 2] - FOOTPRINT_RADIUS
                gap = min(gap, float(d.min()))
                touching.update((rid, int(k)) for k in np.flatnonzero(d <= CONTACT_SLACK))
    result["obstacle_contacts"] = len(touching)
    result["min_obstacle_gap"] = gap
    if plan is None or not truth or plan.frame_robot not in truth[0][1]:
        return
    origin = np.array(truth[0][1][plan.frame_robot][:2])
    seen = np.asarray(plan.obstacles, dtype=np.float64).reshape(-1, 2) + origin
    result["planned_obstacles"] = seen.tolist()
    result["planned_routes"] = {str(r.robot_id): (r.path() + origin).tolist() for r in plan.robots}
    if obs.size and seen.size:
        err = [float(np.min(np.hypot(*(seen - o[:2]).T))) for o in obs]
        result["obstacle_position_error"] = err
        result["obstacles_seen"] = sum(1 for e in err if e < 0.3)


def draw_obstacles(ax: Any, result: dict[str, Any]) -> None:
    """Filled circles for the world's obstacles, dashed ones where the fleet perceived
    them, and the planned routes (dotted) that bend around them."""
    import matplotlib.pyplot as plt

    for x, y, r in result.get("obstacles", []):
        ax.add_patch(plt.Circle((x, y), r, color=OBSTACLE_COLOUR, alpha=0.85))
    for x, y in result.get("planned_obstacles", []):
        ax.add_patch(plt.Circle((x, y), OBSTACLE_RADIUS, fill=False, ec="black", ls="--", lw=0.8))
    for path in result.get("planned_routes", {}).values():
        p = np.asarray(path)
        ax.plot(p[:, 0], p[:, 1], ":", color="black", lw=0.9, alpha=0.7)
