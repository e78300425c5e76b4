"""Static obstacles, plan side (NAO paper 5.1.2, Fig. 17).

The paper's procedure, as we implement it:

1. Obstacles are regarded as robots: the pyramid frame and the pyramid of N + M slots
   are computed from robots *and* obstacles, and both take part in the matching
   (same assignment strategy as the robots alone).
2. The robots walk to their matched slots (the first via point); slots matched to
   obstacles stay empty.
3. The pattern then translates sideways (along ±x_p) out of the obstacle area: the side
   with fewer obstacles beyond the pyramid's axis is chosen (tie: left, -x_p), and the
   shift is the smallest multiple of d_e/4 that puts every slot at least 4·radius
   (two robot diameters) from every obstacle. Each robot's second via point is its
   slot moved by that shift.
4. Starting from the last layer, robots correct the pattern layer by layer: robots
   holding slots of order >= N move into the vacant slots of order < N (those matched
   to obstacles), deepest vacancy first taken by the deepest robot; the final target is
   the vacant slot moved by the shift. Robots already on a slot of order < N stay.

Any shape whose first N slots of N + M are its slots for N (every shape but ``circle`` and
``grid``, :attr:`agent.core.formation.shape.spec.Shape.nested`) takes the pyramid's place
in it; the ``near`` placement below works for every shape.

The path of each robot is thus start -> slot -> shifted slot -> final slot (via points
that coincide with the previous point are dropped). The safety scheduler treats the
obstacles as robots that stand still in every wave, and may replace such a path by a
detour (module :mod:`scheduler`) when it cannot be scheduled safely.

The paper's sideways shift moves the whole pattern out of the obstacle area even when
the obstacles only stand on the way: paths of 3-6 m for six robots whose straight paths
are ~1.5 m, and dead reckoning drifts with the distance walked. The project's ``near``
placement (:func:`plan_near_obstacles`, tried first by :mod:`plan`; translations by
:func:`clear_shifts`) keeps the pattern of the obstacle-free plan and moves it by the
smallest translation, in any direction, that puts every slot ``SLOT_CLEARANCE`` from
every obstacle; the scheduler then bends the paths that pass too close to an obstacle
(via points). Only when that plan cannot be scheduled
safely does the planner fall back to the paper's procedure above.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agent.core.formation.params import CANDIDATES_MAX_N, PlanParams
from agent.core.formation.paths.assignment import assign
from agent.core.formation.shape.layout import centred, placed, shape_frame
from agent.core.formation.waves.scheduled import Scheduled, path_length, scheduled_plan

#: ``near`` placement: a slot's centre stays this many robot radii from an obstacle's
#: centre: the planner's clearance (2·radius) plus one radius for the final visual
#: correction, which steps up to ``max_correction`` (0.3 m) without knowing obstacles.
SLOT_CLEARANCE = 3.0
#: ``near`` placement: translations are tried on rings of step d_e/4, in this many
#: directions (counter-clockwise from +x_p), up to ``SHIFT_RINGS`` rings.
SHIFT_DIRECTIONS = 16
SHIFT_RINGS = 40


def clear_shifts(
    slots: np.ndarray, obs: np.ndarray, step: float, clear: float, extra_rings: int = 1
) -> list[np.ndarray]:
    """Translations (pyramid frame) that put every slot >= ``clear`` from every obstacle.

    Candidates are ``k·step`` along ``SHIFT_DIRECTIONS`` directions, ring k = 0, 1, ...
    (k = 0 is the pattern itself); returned in (k, direction) order: every clear one of
    the first clear ring and of the ``extra_rings`` rings after it. ``ValueError`` when
    no ring up to ``SHIFT_RINGS`` has one.
    """
    if obs.shape[0] == 0:
        return [np.zeros(2)]
    angles = 2.0 * np.pi * np.arange(SHIFT_DIRECTIONS) / SHIFT_DIRECTIONS
    dirs = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    out: list[np.ndarray] = []
    first = -1
    for k in range(SHIFT_RINGS + 1):
        if first >= 0 and k > first + extra_rings:
            break
        cands = np.zeros((1, 2)) if k == 0 else k * step * dirs
        moved = slots[None, :, :] + cands[:, None, :]  # (C, N, 2)
        d = np.hypot(
            moved[:, :, None, 0] - obs[None, None, :, 0],
            moved[:, :, None, 1] - obs[None, None, :, 1],
        )
        ok = d.reshape(cands.shape[0], -1).min(axis=1) >= clear
        if ok.any() and first < 0:
            first = k
        out.extend(cands[j].copy() for j in np.flatnonzero(ok))
    if not out:
        raise ValueError("obstacles: no obstacle-free place for the pyramid near the fleet")
    return out


def plan_near_obstacles(
    pos: np.ndarray, obs: np.ndarray, params: PlanParams, strategy: str
) -> tuple[Scheduled, np.ndarray, float] | None:
    """The ``near`` obstacle plan: (scheduled plan, origin, beta), or None.

    The pyramid frame and centred slots of the robots alone (as without obstacles),
    moved by each translation of :func:`clear_shifts` (slots
    ``SLOT_CLEARANCE``·radius from the obstacles, step d_e/4, the first clear ring and
    the next); each is matched (``strategy``) and scheduled with the obstacles standing
    (detours bend the paths that pass too close). The shortest longest path wins, then
    the smallest total, then the candidate order (ring, direction). Above
    CANDIDATES_MAX_N robots only the first clear translation is tried. None when no
    candidate can be scheduled safely.
    """
    n = pos.shape[0]
    frame = shape_frame(pos, params.axis, params.shape)
    starts_p = frame.to_pyramid(pos)
    slots = placed(params.shape, n, params.d_e, params.phi_e, starts_p, "centroid")
    obs_p = frame.to_pyramid(obs)
    shifts = clear_shifts(slots, obs_p, params.d_e / 4.0, SLOT_CLEARANCE * params.radius)
    if n > CANDIDATES_MAX_N:
        shifts = shifts[:1]
    empty: list[tuple[np.ndarray, ...]] = [() for _ in range(n)]
    best: tuple[float, float, int, Scheduled, np.ndarray] | None = None
    for k, shift in enumerate(shifts):
        moved = slots + shift
        perm = assign(starts_p, moved, strategy, params.d_e, params.phi_e)
        try:
            sc = scheduled_plan(
                pos, frame.to_common(moved[perm]), perm, empty, obs, params, strategy
            )
        except ValueError:
            continue
        lengths = [path_length(pos[r], sc.vias[r], sc.targets[r]) for r in range(n)]
        key = (max(lengths), sc.total, k)
        if best is None or key < best[:3]:
            best = (*key, sc, shift)
    if best is None:
        return None
    shift_c = frame.to_common(best[4]) - frame.to_common(np.zeros(2))
    return best[3], frame.origin + shift_c, frame.beta


@dataclass(frozen=True)
class ObstaclePlan:
    origin: np.ndarray
    beta: float
    shift: np.ndarray  # (2,) translation of the pattern, common frame
    order: np.ndarray  # (N,) final slot order of every robot row (0..N-1)
    vias: list[tuple[np.ndarray, ...]]
    targets: np.ndarray  # (N, 2)


def _shift_needed(
    slots: np.ndarray, obs: np.ndarray, sign: float, step: float, clear: float
) -> float:
    for k in range(0, 4000):
        s = sign * k * step
        moved = slots + np.array([s, 0.0])
        d = np.hypot(moved[:, None, 0] - obs[None, :, 0], moved[:, None, 1] - obs[None, :, 1])
        if d.min() >= clear:
            return abs(s)
    raise ValueError("obstacles: no obstacle-free area found beside the pyramid")


def plan_around_obstacles(
    pos: np.ndarray, obs: np.ndarray, params: PlanParams, strategy: str
) -> ObstaclePlan:
    n, m = pos.shape[0], obs.shape[0]
    if not params.shape.nested:
        raise ValueError(
            f"obstacles: the paper's procedure fills a shape of N + M slots, and the first N "
            f"slots of a {params.shape.name!r} of N + M are not its slots for N"
        )
    everyone = np.vstack([pos, obs])
    frame = shape_frame(everyone, params.axis, params.shape)
    slots_p = centred(params.shape, n + m, params.d_e, params.phi_e)
    perm = assign(frame.to_pyramid(everyone), slots_p, strategy, params.d_e, params.phi_e)
    robot_slot = perm[:n].copy()
    obs_p = frame.to_pyramid(obs)
    step = params.d_e / 4.0
    clear = 4.0 * params.radius
    final_slots = slots_p[:n]
    left_obs = int(np.sum(obs_p[:, 0] < 0))
    right_obs = int(np.sum(obs_p[:, 0] > 0))
    # more obstacles on the left -> move right, and vice versa; tie -> left
    sign = 1.0 if left_obs > right_obs else -1.0
    shift_x = sign * _shift_needed(final_slots, obs_p, sign, step, clear)
    shift_p = np.array([shift_x, 0.0])
    # correction: vacancies < n (matched to obstacles) filled by robots on slots >= n
    vacant = sorted(set(range(n)) - {int(s) for s in robot_slot if s < n})
    movers = sorted((int(s), r) for r, s in enumerate(robot_slot) if s >= n)
    final_order = robot_slot.copy()
    # deepest vacancy <- deepest mover (both sorted by order; pair from the back)
    for vac, (_, r) in zip(reversed(vacant), reversed(movers)):
        final_order[r] = vac
    vias: list[tuple[np.ndarray, ...]] = []
    targets = frame.to_common(slots_p[final_order] + shift_p)
    first = frame.to_common(slots_p[robot_slot])
    second = frame.to_common(slots_p[robot_slot] + shift_p)
    for r in range(n):
        pts = [first[r], second[r]]
        keep: list[np.ndarray] = []
        prev = pos[r]
        for p in pts:
            if np.hypot(*(p - prev)) > 1e-9 and np.hypot(*(p - targets[r])) > 1e-9:
                keep.append(p)
                prev = p
        vias.append(tuple(keep))
    shift_c = frame.to_common(shift_p) - frame.to_common(np.zeros(2))
    return ObstaclePlan(
        origin=frame.origin + shift_c,
        beta=frame.beta,
        shift=shift_c,
        order=final_order,
        vias=vias,
        targets=targets,
    )
