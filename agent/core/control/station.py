"""Station keeping on the parent by vision (AUV paper §II, §V: followers "follow the
leaders or other robots in front of them by visual servoing"; the fleet "should march
in a pattern"; NAO paper 5.1.1 for the pyramid's d_e and φ_e).

A child keeps its parent at the offset the plan defines: at range ``d_ref`` (= d_e)
and bearing ``β*`` in the child's fixed frame (the direction of parent − child in the
plan; every fixed frame is parallel to the common frame, 4.1.1). Each cycle k the
camera measures the parent at range ρ_k and bearing β_k (fixed frame), and

    e_ρ,k = ρ_k − d_ref                          range error (m, > 0: too far)
    e_β,k = wrap(β_k − β*)                       bearing error (rad)
    I_ρ,k = clip(I_ρ,k−1 + e_ρ,k, ±I_ρ,max)      integrals, clamped (anti-windup),
    I_β,k = clip(I_β,k−1 + e_β,k, ±I_β,max)      frozen while the step saturates
    u_ρ = kP·e_ρ,k + kI·I_ρ,k                    PI on range
    u_β = kP·e_β,k + kI·I_β,k                    PI on bearing
    a_k = (1 − λ)·a_k−1 + λ·(q_k − q_k−1)          the parent's advance per cycle, from
                                                 its positions q = p_child + measured
                                                 offset (filtered, λ = 0.5; |a| ≤ max_step)
    Δ_k = u_ρ·r̂(β_k) + ρ_k·u_β·t̂(β_k) + kF·a_k   the child's displacement (fixed frame)

with r̂(β) = (cos β, sin β) towards the parent and t̂(β) = (−sin β, cos β). Moving the
child by Δ moves the parent's relative position by −Δ: the radial part shortens the
range by u_ρ, the tangential part turns the bearing by −u_β (to first order), so
kP = 1, kI = 0 removes a measured error in one step. The parent marches at a roughly
constant speed (a ramp in the reference); a P loop would trail it by a constant lag,
the integral removes that lag, and the feed-forward of the parent's own advance (kF)
keeps up with it from the first cycles on instead of after the integral has grown
(a_k is also where the parent will be next: the prediction for finding it). The
step is speed-limited: |Δ| ≤ ``max_step`` (the
paper's 20 cm, the longest step that walks straight, 4.2), and steps shorter than
``deadband`` are not walked (the measurement noise is larger).

A NAO walks straight and turns on the spot (no side steps through the Body seam), so
Δ is executed as a unicycle (:func:`unicycle_step`): turn at most ``max_turn`` towards
Δ's direction (or towards its opposite when Δ points behind: a step backwards), then
walk Δ's projection on the new heading. The rest of Δ is left to the next cycle.

Pure: no I/O; the caller measures and moves (agent/phases/march.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from agent.core.control.corridor import _finite, closest_approach
from agent.core.control.distance import STEP_LENGTH
from agent.core.control.rotation import wrap_pi


@dataclass(frozen=True)
class StationGains:
    """PI gains of the station keeper (same for range and bearing), and the integral caps.

    Defaults: kP 0.8, kI 0.2. Per cycle, with the parent advancing v, the error obeys
    e_k+1 = e_k + v − u_k, whose characteristic polynomial is
    z² + (kP + kI − 2)·z + (1 − kP) = z² − z + 0.2: real roots 0.72 and 0.28, so a ramp
    is followed without a lag and without oscillation (see the tests)."""

    kp: float = 0.8
    ki: float = 0.2
    kf: float = 0.0  # feed-forward of the parent's advance (agent/phases/march.py uses 0.8)
    i_range_max: float = 1.0  # m·cycles (kI·I must reach the parent's v)
    i_bearing_max: float = 0.6  # rad·cycles

    def __post_init__(self) -> None:
        _finite("kp", self.kp, 0.0, 2.0)
        _finite("ki", self.ki, 0.0, 2.0)
        _finite("kf", self.kf, 0.0, 1.0)
        _finite("i_range_max", self.i_range_max, 0.0)
        _finite("i_bearing_max", self.i_bearing_max, 0.0)
        if self.kp == 0.0:
            raise ValueError("kp must be > 0 (the child would never move)")


@dataclass(frozen=True)
class StationCommand:
    """One cycle's output: displacement (dx, dy) in the fixed frame (m), the errors."""

    dx: float
    dy: float
    e_range: float
    e_bearing: float
    saturated: bool

    @property
    def size(self) -> float:
        return math.hypot(self.dx, self.dy)


@dataclass
class StationKeeper:
    """PI station keeping of one child on its parent (see the module docstring)."""

    d_ref: float
    bearing_ref: float
    gains: StationGains = field(default_factory=StationGains)
    max_step: float = STEP_LENGTH
    deadband: float = 0.03
    i_range: float = 0.0
    i_bearing: float = 0.0
    smoothing: float = 0.5  # λ of the parent's advance filter
    advance: tuple[float, float] = (0.0, 0.0)  # a_k, m per cycle (fixed frame)
    _last_parent: tuple[float, float] | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        _finite("d_ref", self.d_ref, 1e-3)
        self.bearing_ref = wrap_pi(_finite("bearing_ref", self.bearing_ref))
        _finite("max_step", self.max_step, 1e-3, 1.0)
        _finite("deadband", self.deadband, 0.0, self.max_step)
        _finite("smoothing", self.smoothing, 0.0, 1.0)

    def update(
        self, rng: float, bearing: float, position: tuple[float, float] = (0.0, 0.0)
    ) -> StationCommand:
        """The displacement for a parent measured at ``rng`` (m) and ``bearing`` (rad)
        from the child's (dead-reckoned) ``position`` in its fixed frame."""
        rho = _finite("range", rng, 0.0, 100.0)
        beta = _finite("bearing", bearing)
        px, py = (_finite("position", v) for v in position)
        g = self.gains
        q = (px + rho * math.cos(beta), py + rho * math.sin(beta))
        if self._last_parent is not None:
            lam = self.smoothing
            ax = (1 - lam) * self.advance[0] + lam * (q[0] - self._last_parent[0])
            ay = (1 - lam) * self.advance[1] + lam * (q[1] - self._last_parent[1])
            n = math.hypot(ax, ay)
            if n > self.max_step:
                ax, ay = ax * self.max_step / n, ay * self.max_step / n
            self.advance = (ax, ay)
        self._last_parent = q
        e_r = rho - self.d_ref
        e_b = wrap_pi(beta - self.bearing_ref)
        i_r = max(-g.i_range_max, min(g.i_range_max, self.i_range + e_r))
        i_b = max(-g.i_bearing_max, min(g.i_bearing_max, self.i_bearing + e_b))
        u_r = g.kp * e_r + g.ki * i_r
        u_b = g.kp * e_b + g.ki * i_b
        c, s = math.cos(beta), math.sin(beta)
        dx = u_r * c - rho * u_b * s + g.kf * self.advance[0]
        dy = u_r * s + rho * u_b * c + g.kf * self.advance[1]
        size = math.hypot(dx, dy)
        saturated = size > self.max_step
        if saturated:
            dx, dy = dx * self.max_step / size, dy * self.max_step / size
        else:  # conditional integration: no windup while the step is limited
            self.i_range, self.i_bearing = i_r, i_b
        if math.hypot(dx, dy) < self.deadband:
            dx = dy = 0.0
        return StationCommand(dx, dy, e_r, e_b, saturated)

    def reset(self) -> None:
        """Forget the integrals and the parent's advance (after it was lost and found)."""
        self.i_range = self.i_bearing = 0.0
        self.advance = (0.0, 0.0)
        self._last_parent = None


def unicycle_step(
    dx: float,
    dy: float,
    heading: float,
    max_turn: float = math.radians(15.0),
    min_turn: float = math.radians(8.0),
) -> tuple[float, float]:
    """(turn rad, walk m) that carries out the displacement (dx, dy) as far as one
    turn-then-walk can: with α the angle from ``heading`` to the displacement (or to its
    opposite when |α| > 90°, walking backwards), turn τ = clip(α, ±max_turn) (0 when
    |α| < ``min_turn``), then walk ±|Δ|·cos(α − τ)."""
    _finite("dx", dx)
    _finite("dy", dy)
    _finite("heading", heading)
    _finite("max_turn", max_turn, 0.0, math.pi)
    _finite("min_turn", min_turn, 0.0, math.pi)
    size = math.hypot(dx, dy)
    if size == 0.0:
        return 0.0, 0.0
    alpha = wrap_pi(math.atan2(dy, dx) - heading)
    sign = 1.0
    if abs(alpha) > math.pi / 2:
        alpha, sign = wrap_pi(alpha - math.pi), -1.0
    turn = 0.0 if abs(alpha) < min_turn else max(-max_turn, min(max_turn, alpha))
    return turn, sign * size * math.cos(alpha - turn)


def safe_walk(
    walk: float,
    heading: float,
    others: np.ndarray,
    clearance: float,
    fractions: tuple[float, ...] = (1.0, 0.5, 0.25),
) -> float:
    """The safe-step rule on a walk of ``walk`` m along ``heading`` from the origin:
    the longest ``walk·f`` (f in ``fractions``, else 0) whose straight path keeps, for
    every robot at ``others`` (k, 2) relative to us, at least ``clearance`` (2·radius)
    or never comes closer to it than it is now (stepping away from a robot already
    close is allowed). Distance to a point along a segment is convex, so "never closer"
    is "the closest point of the segment is its start"."""
    _finite("walk", walk, -1.0, 1.0)
    _finite("heading", heading)
    _finite("clearance", clearance, 0.0)
    pts = np.asarray(others, dtype=np.float64).reshape(-1, 2)
    if not np.all(np.isfinite(pts)):
        raise ValueError("robot positions must be finite")
    now = np.hypot(pts[:, 0], pts[:, 1])
    u = np.array([math.cos(heading), math.sin(heading)])
    for f in fractions:
        end = walk * f * u
        if float(end @ end) == 0.0:
            return 0.0
        closest = closest_approach(end, pts)
        if np.all((closest >= clearance) | (closest >= now - 1e-12)):
            return walk * f
    return 0.0
