"""The fleet's frame for planning: poses, and the robot left out (DESIGN.md §9).

NAO paper 4.1.3 builds the common frame from positions alone, assuming parallel fixed
frames (4.1.1). Here the common frame carries every robot's start *pose*: the pairing and
robust SE(2) fit of :mod:`poses` (exactly the papers' result when the starts are
aligned), checked by :mod:`pose_check`, which names a robot whose sightings do not fit.

* Nobody named: every robot is planned from its estimated start position, and walks in
  the common frame by turning its own plan by its estimated start heading ψ
  (:mod:`own_frame`).
* One robot named (at least :data:`MIN_BAD_PAIRS` of its pairs misfit), the rest
  connected without it: the rest are fitted again without its
  sightings and without the others' sightings of it (:func:`pose_check.leave_out`); the
  named robot is placed where the *others* saw it (the mean of their sightings of it, in
  the rest's frame), stands still, and is planned around like an obstacle.
* One robot named and the rest not connected, or not consistent, without it: nobody can
  be trusted to move, and :func:`fleet_frame` raises ``ValueError`` with the same reason
  on every agent (they hold the same records).
* Sightings inconsistent with nobody to blame (noise beyond the check's tolerances, as in
  the papers' own Monte Carlo): planned as the papers do, on aligned frames, when that
  model connects the fleet (else on the fit); the robots' own check after hold tells
  whether the pyramid holds.

Deterministic: the same records in any order give bit-identical output (the pose fit's
own guarantee; the named robot's place is a mean over sightings sorted by owner id).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from agent.core.formation.common_frame import build_common_frame
from agent.core.formation.neighbour_check import identify_neighbours
from agent.core.formation.pose_check import check_poses, leave_out
from agent.core.formation.poses import (
    POS_TOL,
    POS_TOL_REL,
    PoseFrame,
    evaluate_poses,
    pair_measurements,
)
from agent.core.formation.records import NeighborRecord


@dataclass(frozen=True)
class FleetFrame:
    """Poses of the robots to plan, in the frame robot's fixed frame, and who is left out."""

    frame_robot: int
    ids: tuple[int, ...]  # ascending: the robots to plan
    positions: np.ndarray  # (N, 2)
    headings: np.ndarray  # (N,) ψ: each robot's fixed frame turned from the common frame
    aligned: bool  # the papers' aligned model was kept (every ψ exactly 0)
    excluded: tuple[int, ...] = ()  # robots left out: they stand still
    #: (len(excluded), 2): where the others saw the robots left out
    excluded_at: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    reason: str = ""  # the consistency check's verdict

    def heading_of(self, robot_id: int) -> float:
        """ψ of a planned robot; ``ValueError`` for one not planned."""
        if robot_id not in self.ids:
            raise ValueError(f"robot {robot_id} is not planned")
        return float(self.headings[self.ids.index(robot_id)])


def _seen_by_others(poses: PoseFrame, rest: PoseFrame, robot: int) -> np.ndarray:
    """Where the rest saw ``robot``: the mean of their sightings of it, in ``rest``'s frame."""
    seen = [
        rest.to_common(m.owner, m.vector)[0]
        for m in sorted(poses.measurements, key=lambda m: (m.owner, m.target))
        if m.target == robot and m.owner in rest.ids
    ]
    if not seen:  # nobody else saw it (it only saw them): its own estimate, mapped
        k = poses.ids.index(robot)
        return _map_point(poses, rest, poses.positions[k])
    return np.asarray(np.mean(np.array(seen), axis=0))


def _map_point(src: PoseFrame, dst: PoseFrame, point: np.ndarray) -> np.ndarray:
    """A point of ``src``'s frame in ``dst``'s, through their common robots (a 2-D rigid
    least-squares fit of the shared positions)."""
    common = [i for i in dst.ids if i in src.ids]
    a = np.array([src.positions[src.ids.index(i)] for i in common])
    b = np.array([dst.positions[dst.ids.index(i)] for i in common])
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    h = (a - ca).T @ (b - cb)
    u, _, vt = np.linalg.svd(h)
    r = vt.T @ u.T
    if np.linalg.det(r) < 0:
        vt[-1] *= -1
        r = vt.T @ u.T
    return np.asarray(cb + r @ (np.asarray(point, dtype=np.float64) - ca))


#: A robot is left out only when at least this many of its pairs misfit *in position*: a
#: single misfit pair (a neighbour half hidden) could be either end's fault, and masks
#: alone (wrong matches are common: a sound robot of an aligned 4-NAO fleet was left out
#: on two 47° mask misfits) never leave a robot out. A record turned as a whole fits in
#: position (its ψ absorbs it); the parent's mask in every child's own check is what
#: catches the bent pair then (agent/phases/hold.py).
MIN_BAD_PAIRS = 2


def _bad_pairs(poses: PoseFrame, robot: int) -> int:
    """Pairs of ``robot`` whose sightings misfit in position beyond the tolerance."""
    return sum(
        1
        for q in poses.pairs
        if robot in (q.i, q.j) and q.position > POS_TOL + POS_TOL_REL * q.distance
    )


def _aligned_explains(
    records: Sequence[NeighborRecord], epsilon: float, pairs: int
) -> PoseFrame | None:
    """The papers' model (eq. 9 pairs, least squares, ψ ≡ 0) when it pairs at least
    ``pairs`` robot pairs and every one fits in position; else None."""
    graph = identify_neighbours(records, epsilon)
    try:
        cf = build_common_frame(graph, "lsq")
    except ValueError:
        return None
    meas = pair_measurements(graph)
    cand = evaluate_poses(cf.ids, meas, cf.positions, np.zeros(len(cf.ids)), cf.frame_robot, True)
    return cand if cand.positions_consistent and len(cand.pairs) >= pairs else None


def _papers_model(records: Sequence[NeighborRecord], epsilon: float) -> FleetFrame | None:
    """Today's common frame (eq. 9 pairs, least squares, ψ ≡ 0), or None if not connected."""
    try:
        cf = build_common_frame(identify_neighbours(records, epsilon), "lsq")
    except ValueError:
        return None
    return FleetFrame(cf.frame_robot, cf.ids, cf.positions, np.zeros(len(cf.ids)), True)


def fleet_frame(records: Sequence[NeighborRecord], epsilon: float) -> FleetFrame:
    """Pair, fit, check and, if needed, leave one robot out (module docstring).

    Raises ``ValueError`` for bad records, a fleet the mutual pairs do not connect, a
    named robot without which the rest is not connected, or a fleet whose sightings are
    inconsistent beyond one robot.
    """
    verdict = check_poses(records, epsilon)
    poses = verdict.poses
    today = _aligned_explains(records, epsilon, len(poses.pairs))
    if today is not None:
        # the papers' aligned model pairs as many robots and explains every position:
        # exactly today's frame, nobody left out on masks alone (a turned record would
        # misfit in position there)
        return FleetFrame(
            today.frame_robot, today.ids, today.positions, today.headings, True,
            reason="aligned starts: every sighting fits in position",
        )  # fmt: skip
    if verdict.named and _bad_pairs(poses, verdict.named[0]) < MIN_BAD_PAIRS:
        # one misfit pair (a wrong mask, a robot half hidden) blames neither end alone
        verdict = replace(
            verdict,
            named=(),
            reason=f"nobody named, < 2 pairs misfit in position: {verdict.reason}",
        )
    if not verdict.named:
        if not poses.consistent:
            # noisy sightings no single robot explains: plan as the papers do (aligned
            # frames, least squares) when that model connects the fleet, else on the fit;
            # the robots' own check after hold says whether the result holds
            papers = _papers_model(records, epsilon)
            if papers is not None:
                return replace(papers, reason=f"{verdict.reason}; planned on aligned frames")
        return FleetFrame(
            poses.frame_robot, poses.ids, poses.positions, poses.headings, poses.aligned,
            reason=verdict.reason,
        )  # fmt: skip
    (robot,) = verdict.named[:1]
    rest = leave_out(poses, robot)
    if rest is None or not rest.consistent:
        raise ValueError(
            f"robot {robot}'s sightings do not fit ({verdict.reason}) and the rest is not a "
            "connected, consistent fleet without it; nobody moves"
        )
    at = _seen_by_others(poses, rest, robot)
    return FleetFrame(
        rest.frame_robot,
        rest.ids,
        rest.positions,
        rest.headings,
        rest.aligned,
        excluded=(robot,),
        excluded_at=at.reshape(1, 2),
        reason=verdict.reason,
    )
