"""Step 3 of the fault test (:mod:`fault_test`): the others' masks of a robot, and whether
they agree on one offset from its fitted heading (docs/design.md §9, item 3).

A robot whose compass is broken has its own sightings turned: its estimated ψ absorbs
the turn, positions all fit, and only the others' masks of it (modulo π) disagree, all
by one offset Δ. With the mask model's density f (:class:`SightingNoise`: the correct
mask, the side/front confusion at ±90°, uniform otherwise), the generalised likelihood
ratio ``2·max_Δ Σ log f(δ_k − Δ)/f(δ_k)`` over the others' masks δ_k of r, divided by
its measured null scale, is χ²₁ under "r is sound" (Wilks; Δ on a 1° grid). The floor
``rho`` the fault test puts under it is the fault test's.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy.special import chdtrc

from agent.core.formation.frame.poses import PoseFrame, PoseMeasurement
from agent.core.perception.sighting_noise import SightingNoise

#: The mask offsets Δ the heading test weighs (step 3): every degree of the half circle.
MASK_GRID = np.radians(np.arange(0.0, 180.0, 1.0))


def mask_test(deltas: Sequence[float], noise: SightingNoise) -> tuple[float, float]:
    """(Δ, p-value) of the heading test of step 3 over mask misfits ``deltas`` (rad): Wilks'
    statistic divided by the measured null scale ``noise.mask_scale``, against χ²₁."""
    d = np.asarray(deltas, dtype=np.float64)
    if d.size == 0:
        return 0.0, 1.0
    logf = np.log(noise.mask_density(d[None, :] - MASK_GRID[:, None])).sum(axis=1)
    best = int(np.argmax(np.round(logf, 12)))  # the first (smallest Δ) of equal maxima
    stat = max(0.0, 2.0 * float(logf[best] - logf[0]))
    offset = float((MASK_GRID[best] + math.pi / 2) % math.pi - math.pi / 2)
    return offset, float(chdtrc(1, stat / noise.mask_scale))


def mask_deltas(poses: PoseFrame, target: int) -> list[float]:
    """δ = ψ_t − ψ_o − (β + θ − π/2) of the others' masks of ``target`` (by owner id)."""
    return mask_deltas_of(poses.ids, poses.headings, poses.measurements, target)


def mask_deltas_of(
    ids: Sequence[int], headings: np.ndarray, measurements: Sequence[PoseMeasurement], target: int
) -> list[float]:
    """:func:`mask_deltas` of ``measurements`` between robots ``ids`` at ``headings``."""
    index = {rid: k for k, rid in enumerate(ids)}
    out = []
    # filtered, then sorted (stably): the order of the sorted list, filtered
    of_it = (m for m in measurements if m.target == target)
    for m in sorted(of_it, key=lambda m: (m.owner, m.target)):
        if not math.isfinite(m.orientation):
            continue
        ref = math.atan2(float(m.vector[1]), float(m.vector[0])) + m.orientation - math.pi / 2
        out.append(float(headings[index[target]] - headings[index[m.owner]] - ref))
    return out
