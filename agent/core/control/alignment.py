"""Final visual alignment to the parent: where to look, which NAO is the parent.

An addition to the papers (NAO paper 5.2.2 walks the plan open loop; AUV paper II has
each robot follow the robot in front by visual servoing). Once the fleet has arrived,
a child looks at its parent and steps by the difference between the measured and the
planned offset (``agent.phases.hold.Hold.correct``). Two things make that fragile:

- the parent need not be in the one image taken at the expected bearing: the heading
  belief drifts over long walks, a NAO cut by the image border is not detected, and an
  obstacle or another NAO may hide it from that view. :func:`look_yaws` gives head yaws
  fanned out around the expected bearing (expected first, then alternately left and
  right by ``spread``), clipped to the head's reach, without repeats;
- the nearest NAO to the expected position, wherever it is, may be another robot.
  :func:`match_parent` only accepts a NAO within ``gate`` of the expected position
  (the largest correction a robot walks), the nearest of those; ties go to the lower
  index (detection order).
"""

from __future__ import annotations

import math

import numpy as np

from agent.core.control.rotation import wrap_pi

#: Yaw offsets of :func:`look_yaws`, in multiples of ``spread``, in the order looked.
FAN = (0, 1, -1, 2, -2)


def look_yaws(bearing: float, heading: float, spread: float, limit: float) -> list[float]:
    """Head yaws (rad, + left) to look for a NAO expected at ``bearing`` (fixed frame)
    from a body believed at ``heading``: the expected yaw, then ± ``spread``, ± 2
    ``spread``; each clipped to [-limit, limit], repeats (within 1e-9) dropped.

    ``ValueError`` for a negative or non-finite ``spread`` or ``limit``, non-finite angles.
    """
    for name, v in (("spread", spread), ("limit", limit)):
        if not math.isfinite(v) or v < 0:
            raise ValueError(f"{name} must be a finite angle >= 0, got {v!r}")
    if not (math.isfinite(bearing) and math.isfinite(heading)):
        raise ValueError("bearing and heading must be finite")
    centre = wrap_pi(bearing - heading)
    out: list[float] = []
    for k in FAN:
        yaw = float(np.clip(centre + k * spread, -limit, limit))
        if all(abs(yaw - y) > 1e-9 for y in out):
            out.append(yaw)
    return out


def match_parent(points: np.ndarray, expected: np.ndarray, gate: float) -> int | None:
    """Index of the NAO (``points`` (K, 2), fixed frame, relative to the child) nearest to
    ``expected`` (2,) among those within ``gate`` (m) of it; None if there is none.

    ``ValueError`` on bad shapes, non-finite values or a gate that is not > 0.
    """
    pts = np.asarray(points, dtype=np.float64)
    exp = np.asarray(expected, dtype=np.float64)
    if pts.size == 0:
        pts = pts.reshape(0, 2)
    if pts.ndim != 2 or pts.shape[1] != 2 or exp.shape != (2,):
        raise ValueError(f"points must be (K, 2) and expected (2,), got {pts.shape}, {exp.shape}")
    if not (np.all(np.isfinite(pts)) and np.all(np.isfinite(exp))):
        raise ValueError("points and expected must be finite")
    if not (math.isfinite(gate) and gate > 0):
        raise ValueError(f"gate must be a finite distance > 0, got {gate!r}")
    if pts.shape[0] == 0:
        return None
    d = np.hypot(pts[:, 0] - exp[0], pts[:, 1] - exp[1])
    k = int(np.argmin(d))  # argmin: the first of equal distances
    return k if d[k] <= gate else None
