"""The heading re-measured after a crash: the estimate and the compass weighed by their
errors (NAO paper 3.2.1, the visual compass, eq. 2; docs/design.md §1, crash recovery).

A robot resumed after its agent crashed turns to θ = 0 by its estimate and measures its
heading against the reference view, the head-yaw-0 image that defines its fixed frame,
taken at the frame's origin. The two are weighed here.

**The compass away from its reference.** The compass assumes that two images differ by a
pure rotation. A robot that has walked d metres from the reference view's place sees the
room with parallax, and the turn it reads is off by about 12–15° per metre. Measured in the
4 m room (``python -m tools.eval_perception --views 1 --compass-samples 0 --compass-away
60 --seed 12``): rms 0.19° in place, 3.0° at 0.25 m, 6.0° at 0.5 m, 11.5° at 1 m, 18° at
1.5 m (``--renderer egl``: the same within 0.3°, and 26.5° at 2 m); most readings a metre
away fail outright (too few matches), the rest are wrong by that much. So

    σ_c(d)² = σ_0² + (k·d)²,   σ_0 = 0.2°,  k = 14°/m (the upper end).

**The estimate.** Its error is σ_e² = σ_b² + σ_f². σ_b = 2° is the belief's own error: the
compass-measured motion of a plan (about ten 20 cm steps at σ 0.15° and a few turns at
≤ 0.7°, docs/results.md "visual compass"), rounded up. σ_f is the error of the command in
flight at the crash, which the beliefs count by its commanded value without measuring it:

* a turn of v: 5 % of |v| + 0.02 rad, the NAO's turn error (the world's gait draws the
  same figures, docs/design.md §4);
* a step of s metres (forwards or sideways): 0.5 rad/m · |s|, the upper end of the open-loop
  heading drift of the NAO paper's Table 2;
* a command whose execution is unknown (a body without request ids): its whole value
  besides, for a turn (the robot may not have turned at all).

**The update** is the scalar Kalman update with a χ² gate. The innovation
ν = wrap(measured − estimate) is accepted when ν² ≤ χ²₁(1 − α)·(σ_e² + σ_c²), α = 10⁻³
(|ν| ≤ 3.29 σ), and the heading becomes estimate + K·ν with K = σ_e² / (σ_e² + σ_c²);
a rejected innovation keeps the estimate (a compass that matched the wrong features).
Near the reference place the compass wins (K ≈ 0.99 in place); a metre away it barely
moves the estimate (K ≈ 0.02), so parallax cannot turn a sound estimate by 14°.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from agent.core.control.rotation import wrap_pi

#: The compass's error at its reference view's place, rad (σ_0).
COMPASS_IN_PLACE = math.radians(0.2)
#: The compass's parallax error per metre from its reference view's place, rad/m (k).
COMPASS_AWAY = math.radians(14.0)
#: The belief's own heading error after a plan's compass-measured motion, rad (σ_b).
BELIEF_SIGMA = math.radians(2.0)
#: A turn counted unmeasured: its relative and absolute error (rad/rad, rad).
TURN_ERROR = (0.05, 0.02)
#: A step counted unmeasured: its heading drift, rad per metre.
STEP_DRIFT = 0.5
#: The gate's χ²₁ quantile at α = 10⁻³.
GATE_CHI2 = 10.828


@dataclass(frozen=True)
class HeadingFix:
    """The fused heading (rad), its σ, the gain and whether the measurement was taken."""

    heading: float
    sigma: float
    gain: float
    accepted: bool
    innovation: float
    sigma_compass: float


def _finite(**values: float) -> None:
    for name, v in values.items():
        if not math.isfinite(v):
            raise ValueError(f"{name} must be finite, got {v!r}")


def compass_sigma(away: float) -> float:
    """σ_c of the compass measured ``away`` metres from its reference view's place (rad)."""
    _finite(away=away)
    if away < 0:
        raise ValueError(f"away must be >= 0, got {away!r}")
    return math.hypot(COMPASS_IN_PLACE, COMPASS_AWAY * away)


def estimate_sigma(command: str = "", value: float = 0.0, known: bool = True) -> float:
    """σ_e of the heading estimate after the command in flight (``""``: none; ``turn``, rad;
    ``walk`` or ``side``, m) was counted unmeasured; ``known``: its execution was reported
    (a request id), not assumed."""
    _finite(value=value)
    if command == "":
        return BELIEF_SIGMA
    if command == "turn":
        flight = TURN_ERROR[0] * abs(value) + TURN_ERROR[1]
        if not known:
            flight = math.hypot(flight, value)
    elif command in ("walk", "side"):
        flight = STEP_DRIFT * abs(value)
    else:
        raise ValueError(f"command must be '', 'turn', 'walk' or 'side', got {command!r}")
    return math.hypot(BELIEF_SIGMA, flight)


def fuse(estimate: float, sigma_e: float, measured: float, sigma_c: float) -> HeadingFix:
    """The heading from the ``estimate`` (σ ``sigma_e``) and the compass's ``measured``
    (σ ``sigma_c``), all in radians: the Kalman update, or the estimate when the χ² gate
    rejects the innovation."""
    _finite(estimate=estimate, sigma_e=sigma_e, measured=measured, sigma_c=sigma_c)
    if sigma_e <= 0 or sigma_c <= 0:
        raise ValueError(f"sigmas must be > 0, got {sigma_e!r}, {sigma_c!r}")
    nu = wrap_pi(measured - estimate)
    s2 = sigma_e**2 + sigma_c**2
    gain = sigma_e**2 / s2
    if nu * nu > GATE_CHI2 * s2:
        return HeadingFix(wrap_pi(estimate), sigma_e, 0.0, False, nu, sigma_c)
    return HeadingFix(
        wrap_pi(estimate + gain * nu), math.sqrt(gain) * sigma_c, gain, True, nu, sigma_c
    )
