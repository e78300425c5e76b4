"""Start sidesteps: a robot whose straight path runs past other robots' starts steps aside
first (to bring the planner's worst makespan to at most 2× CAPT's; our addition to NAO paper 4.2's
straight paths, kept to the safety rule of :mod:`safety` by the scheduler as every via point is).

The worst fleet of ``python -m tools.bench plan`` is a line: tens of robots stand in one
column and walk along it to the pyramid. Each straight path then runs within the
clearance of the starts ahead of it, so every robot waits until the one ahead has left
and its path has drawn away, which on nearly parallel paths is far (a chain of waits).
A sidestep at the start - one via point ``KINK_ALONG`` clearances along the straight
path and ``KINK_OFFSET`` clearances beside it - puts the robot on a lane of its own
beside the column before it passes anyone's start, and every robot of the bundle steps
the same way, so their first legs are parallel.

Which robots: those whose straight path is at least ``KINK_MIN_LENGTH`` clearances long
and passes within ``KINK_NEAR`` clearances of another robot's start (ahead of its own
start). Which side: away from the pyramid's axis, the side its path already drifts to
(the component of start -> slot across the axis ``axis``; none: the left of the path).
The plan stays one candidate among others (:mod:`choice`): it is kept only when its
makespan is the smallest.
"""

from __future__ import annotations

import numpy as np

from agent.core.formation.paths.geometry import point_seg_dist

#: The via point: this many clearances along the straight path from the start ...
KINK_ALONG = 5.0
#: ... and this many clearances beside it.
KINK_OFFSET = 1.5
#: Only straight paths at least this many clearances long get a sidestep.
KINK_MIN_LENGTH = 20.0
#: A path "runs past" a start that lies within this many clearances of it.
KINK_NEAR = 2.0


def start_kinks(
    starts: np.ndarray, targets: np.ndarray, axis: np.ndarray, clearance: float
) -> list[tuple[np.ndarray, ...]]:
    """Per robot row: one via point (the sidestep) or none. ``axis``: the pyramid's
    facing direction (unit vector, same frame as the points); ``clearance``: 2·radius."""
    p = np.asarray(starts, dtype=np.float64)
    q = np.asarray(targets, dtype=np.float64)
    e = np.asarray(axis, dtype=np.float64)
    n = p.shape[0]
    out: list[tuple[np.ndarray, ...]] = [() for _ in range(n)]
    d = q - p
    length = np.hypot(d[:, 0], d[:, 1])
    long_ = np.flatnonzero(length >= KINK_MIN_LENGTH * clearance)
    if long_.size == 0 or n < 2:
        return out
    # distance of every start to every long path (rows: paths); own start excluded
    dist = point_seg_dist(p[None, :, :], p[long_, None, :], q[long_, None, :])
    dist[np.arange(long_.size), long_] = np.inf
    ahead = np.einsum("kjd,kd->kj", p[None, :, :] - p[long_, None, :], d[long_])
    near = (dist < KINK_NEAR * clearance) & (ahead > 0.0)
    for k, i in enumerate(long_.tolist()):
        if not near[k].any():
            continue
        u = d[i] / length[i]
        nrm = np.array([-u[1], u[0]])  # left of the path
        across = d[i] - float(d[i] @ e) * e
        if float(nrm @ across) < -1e-9 * length[i]:
            nrm = -nrm
        out[i] = (p[i] + KINK_ALONG * clearance * u + KINK_OFFSET * clearance * nrm,)
    return out
