"""Is the formation right? One formula for the robots' own check and the ground truth's.

NAO paper 5.1.1 measures a built pyramid pair by pair: for a child and its parent, the
distance d between them and the angle φ between the line parent → child and the
pyramid's backward axis, as relative errors

    r_d = (d − d_e) / d_e,        r_φ = (φ − φ_e) / φ_e.

A pair is *in tolerance* when |r_d| <= :data:`R_D_MAX` and |r_φ| <= :data:`R_PHI_MAX`
(the papers' simulations report r_d mainly within ±20 % and r_φ within ±30 %; the real
NAOs of 5.2 hold ±0.1 m at d_e = 0.8 m, i.e. 12.5 %).

"Done" is a measurement, not an assumption (docs/design.md §9): after hold each child
measures its parent with the camera and judges the pair with :func:`check_pair`; the
evaluation tools judge the ground truth with the same function. A child whose own start
heading is misjudged measures in a turned frame and would find a bent pair in tolerance;
the parent's mask (the M-base orientation of the NAO seen, relative to the line of sight)
does not depend on that frame: every robot of a held pyramid faces the axis, so
:func:`facing_misfit` compares the parent's facing with the axis the child believes in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

#: Largest |r_d| of a pair in tolerance (0.1 m at the real NAOs' d_e = 0.8 m).
R_D_MAX = 0.125
#: Largest |r_φ| of a pair in tolerance.
R_PHI_MAX = 0.30
#: The share of the tolerances a robot's own check allows itself (:attr:`PairCheck.sure`).
OWN_MARGIN = 0.8


@dataclass(frozen=True)
class PairCheck:
    """One child–parent pair: distance (m), angle off the backward axis (rad), r_d, r_φ."""

    child: int
    parent: int
    distance: float
    angle: float
    r_d: float
    r_phi: float

    @property
    def ok(self) -> bool:
        return abs(self.r_d) <= R_D_MAX and abs(self.r_phi) <= R_PHI_MAX

    @property
    def sure(self) -> bool:
        """In tolerance with :data:`OWN_MARGIN` to spare: what a robot's own camera
        check demands before it says done (its measurement errs too: ~3 % in distance,
        a few degrees in angle)."""
        return abs(self.r_d) <= OWN_MARGIN * R_D_MAX and abs(self.r_phi) <= OWN_MARGIN * R_PHI_MAX

    def text(self) -> str:
        """``r_d +3.1 %, r_φ −54.0 % to parent 1`` (for statuses and logs)."""
        return f"r_d {self.r_d:+.1%}, r_φ {self.r_phi:+.1%} to parent {self.parent}"


def check_pair(
    child: int,
    parent: int,
    offset: np.ndarray,
    axis: float,
    d_e: float,
    phi_e: float,
) -> PairCheck:
    """Judge a pair from ``offset`` = parent − child (m), in a frame where the pyramid's
    axis points at ``axis`` (rad, CCW from +x).

    Raises ``ValueError`` for a non-finite offset or axis, a zero offset, or d_e, φ_e
    that are not positive.
    """
    v = np.asarray(offset, dtype=np.float64).reshape(-1)
    if v.shape != (2,) or not np.all(np.isfinite(v)):
        raise ValueError(f"offset must be two finite numbers, got {offset!r}")
    if not math.isfinite(axis):
        raise ValueError(f"axis must be finite, got {axis}")
    if not (d_e > 0.0 and phi_e > 0.0 and math.isfinite(d_e) and math.isfinite(phi_e)):
        raise ValueError(f"d_e and phi_e must be positive, got {d_e}, {phi_e}")
    d = float(math.hypot(float(v[0]), float(v[1])))
    if d == 0.0:
        raise ValueError("child and parent at the same point")
    # parent − child points forward along the axis, φ_e to one side
    cosang = (float(v[0]) * math.cos(axis) + float(v[1]) * math.sin(axis)) / d
    phi = math.acos(min(1.0, max(-1.0, cosang)))
    return PairCheck(child, parent, d, phi, (d - d_e) / d_e, (phi - phi_e) / phi_e)


def check_edge(
    child: int,
    parent: int,
    offset: np.ndarray,
    axis: float,
    distance: float,
    angle: float,
    phi_e: float,
) -> PairCheck:
    """Judge a pair of any shape's tree (:mod:`agent.core.formation.shape.tree`) from
    ``offset`` = parent − child (m), in a frame where the shape's axis points at ``axis``
    (rad, CCW from +x): the child belongs ``distance`` from its parent at ``angle`` (rad,
    CCW from the facing).

    r_d = (d − distance) / distance; r_φ = δ / φ_e, δ the signed angle (wrapped to
    (−π, π]) from the tree's direction parent → child to the measured one, counted
    positive away from the backward axis on the child's own side (clockwise for a child
    on its parent's left, counter-clockwise on its right or straight ahead or behind):
    for the pyramid's pairs (distance d_e, angle ±(π − φ_e)) exactly NAO paper 5.1.1's
    r_d and (φ − φ_e)/φ_e on the child's own side, and a child on the wrong side has r_φ
    near −200 %. ``angle`` of the result: the measured direction parent → child, CCW
    from the facing. ``ValueError`` as :func:`check_pair`.
    """
    v = np.asarray(offset, dtype=np.float64).reshape(-1)
    if v.shape != (2,) or not np.all(np.isfinite(v)):
        raise ValueError(f"offset must be two finite numbers, got {offset!r}")
    if not (math.isfinite(axis) and math.isfinite(angle)):
        raise ValueError(f"axis and angle must be finite, got {axis}, {angle}")
    if not (distance > 0.0 and phi_e > 0.0 and math.isfinite(distance) and math.isfinite(phi_e)):
        raise ValueError(f"distance and phi_e must be positive, got {distance}, {phi_e}")
    d = float(math.hypot(float(v[0]), float(v[1])))
    if d == 0.0:
        raise ValueError("child and parent at the same point")
    # the direction parent → child (−offset), CCW from the facing
    seen = math.remainder(math.atan2(-float(v[1]), -float(v[0])) - axis, 2.0 * math.pi)
    delta = math.remainder(seen - angle, 2.0 * math.pi)
    side = math.sin(angle)  # > 0: the child belongs on its parent's left
    sign = -1.0 if side > 1e-12 else 1.0
    return PairCheck(child, parent, d, seen, (d - distance) / distance, sign * delta / phi_e)


def facing_tolerance(sigma_mask: float, alpha: float) -> float:
    """The largest :func:`facing_misfit` (rad) of a sound pair at false-alarm rate
    ``alpha``: both robots face the axis, so the misfit is the mask's own error, N(0, σ_m)
    for a mask read right (the sighting noise model, docs/design.md §9), and
    ``z_{1−α/2} σ_m`` bounds it two-sided. At the fault test's α = 10⁻⁴ and the shipped
    σ_m of 6.7°: 26°. Raises ``ValueError`` for σ_m outside (0, π/4) or α outside (0, 1).
    """
    if not 0.0 < sigma_mask < math.pi / 4:
        raise ValueError(f"sigma_mask must be in (0, π/4), got {sigma_mask}")
    if not 0.0 < alpha < 1.0:
        raise ValueError(f"alpha must be in (0, 1), got {alpha}")
    return NormalDist().inv_cdf(1.0 - alpha / 2.0) * sigma_mask


def facing_misfit(offset: np.ndarray, facing: float, axis: float) -> float:
    """How far (rad, modulo π, in (−π/2, π/2]) the parent seen at ``offset`` (parent −
    child) with mask orientation ``facing`` (its heading minus the line of sight) faces
    from ``axis``, the pyramid axis in the child's frame. Modulo π: a mask may confuse
    front and back. Raises ``ValueError`` for non-finite input or a zero offset.
    """
    v = np.asarray(offset, dtype=np.float64).reshape(-1)
    if v.shape != (2,) or not np.all(np.isfinite(v)) or not math.hypot(*v) > 0.0:
        raise ValueError(f"offset must be two finite numbers, not both 0, got {offset!r}")
    if not (math.isfinite(facing) and math.isfinite(axis)):
        raise ValueError(f"facing and axis must be finite, got {facing}, {axis}")
    los = math.atan2(float(v[1]), float(v[0]))
    d = (facing - (axis - los)) % math.pi
    return d - math.pi if d > math.pi / 2 else d
