"""Kinematic control of one NAO (NAO paper 4.2, 5.2.2): rotation PID and distance steps."""

from agent.core.control.distance import STEP_LENGTH, Leg, advance, next_leg, split_distance
from agent.core.control.rotation import (
    MAX_STEP,
    PAPER_GAINS,
    STEP_GAINS,
    PidGains,
    RotationControl,
    wrap_pi,
)

__all__ = [
    "MAX_STEP",
    "PAPER_GAINS",
    "STEP_GAINS",
    "STEP_LENGTH",
    "Leg",
    "PidGains",
    "RotationControl",
    "advance",
    "next_leg",
    "split_distance",
    "wrap_pi",
]
