"""Where the fleet's common frame lies in the world, for evaluation (docs/design.md §9).

The common frame is the frame robot's fixed frame *as it believes it*: its start pose if
its sensors are right, turned and moved if its record is not (an injected
``--sensor-fault``, a compass off by a constant). Mapping the plan to the world through
the frame robot's true start pose would then judge a correct pyramid as bent. The
evaluator instead fits the rigid motion (2-D least squares, Kabsch/Umeyama without
scale) that takes the plan's start positions to the planned robots' true starts.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np


def common_frame_pose(
    plan_starts: Mapping[int, np.ndarray], true_starts: Mapping[int, tuple[float, float, float]]
) -> tuple[float, float, float]:
    """(x, y, h) such that a common-frame point p is ``(x, y) + R(h − π/2) p`` in the world.

    ``plan_starts``: robot id -> start in the common frame; ``true_starts``: robot id ->
    its true start pose (x, y, heading). Uses the robots in both (at least two; with one,
    its true heading is taken as the frame's). Raises ``ValueError`` with none in common.
    """
    ids = sorted(i for i in plan_starts if i in true_starts)
    if not ids:
        raise ValueError("no planned robot has a true start")
    a = np.array([np.asarray(plan_starts[i], dtype=np.float64).reshape(2) for i in ids])
    b = np.array([true_starts[i][:2] for i in ids], dtype=np.float64)
    if len(ids) == 1:
        turn = float(true_starts[ids[0]][2]) - math.pi / 2
    else:
        ca, cb = a.mean(axis=0), b.mean(axis=0)
        h = (a - ca).T @ (b - cb)
        turn = math.atan2(float(h[0, 1] - h[1, 0]), float(h[0, 0] + h[1, 1]))
    c, s = math.cos(turn), math.sin(turn)
    offset = b.mean(axis=0) - a.mean(axis=0) @ np.array([[c, s], [-s, c]])
    return float(offset[0]), float(offset[1]), turn + math.pi / 2


def frame_error(
    estimated: Mapping[int, tuple[np.ndarray, float]],
    true_starts: Mapping[int, tuple[float, float, float]],
) -> tuple[float, float]:
    """Worst position (m) and start-heading (rad) error of estimated starts (robot id ->
    (position in the common frame, ψ)) against the truth, after the rigid motion of
    :func:`common_frame_pose`. A robot faces +y (π/2) in its own fixed frame, so its true
    heading is h + ψ. Robots without a true start are ignored."""
    ids = sorted(i for i in estimated if i in true_starts)
    x, y, h = common_frame_pose({i: estimated[i][0] for i in ids}, true_starts)
    c, s = math.cos(h - math.pi / 2), math.sin(h - math.pi / 2)
    turn = np.array([[c, -s], [s, c]])
    pos = max(
        float(np.hypot(*(np.array([x, y]) + turn @ estimated[i][0] - np.array(true_starts[i][:2]))))
        for i in ids
    )
    psi = max(
        abs(math.remainder(true_starts[i][2] - (h + estimated[i][1]), 2 * math.pi)) for i in ids
    )
    return pos, psi


def truth_in_frame(
    true_starts: Mapping[int, tuple[float, float, float]], ids: Sequence[int], frame: int
) -> tuple[np.ndarray, np.ndarray]:
    """True start poses of ``ids`` in robot ``frame``'s fixed frame, as the fleet's common
    frame writes poses (the inverse of :func:`common_frame_pose` with the frame robot's
    true start): positions (n, 2) and headings ψ (n,), ψ of ``frame`` 0.

    Raises
    ------
    ValueError
        ``frame`` or a robot of ``ids`` has no true start.
    """
    missing = [i for i in (frame, *ids) if i not in true_starts]
    if missing:
        raise ValueError(f"no true start for robots {sorted(set(missing))}")
    xf, yf, hf = true_starts[frame]
    c, s = math.cos(hf - math.pi / 2), math.sin(hf - math.pi / 2)
    rel = np.array([true_starts[i][:2] for i in ids], dtype=np.float64) - (xf, yf)
    pos = np.stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]], axis=1)
    psi = np.array([math.remainder(true_starts[i][2] - hf, 2 * math.pi) for i in ids])
    return pos.reshape(-1, 2), psi
