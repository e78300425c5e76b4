"""Injected sensor faults: a test tool for the fleet's consistency check (docs/design.md §9).

The papers trust every record (NAO paper 4.1.2). A real robot can be wrong about what it
saw, and the fleet must notice. For evaluation an agent can corrupt its *own* record,
after localisation (NAO paper 3.2, eqs. 7-8) and before it is published, in one of three
ways that mirror what goes wrong on a real floor:

* ``rotate:DEG`` - a broken compass: every sighting turned by DEG degrees about the
  robot (the mask orientations, relative to each line of sight, stay as they are);
* ``scale:F`` - a miscalibrated D-base (eq. 6): every distance multiplied by F;
* ``shift:M`` - an insider that lies with its own key: every sighting moved by M metres
  along +x of its fixed frame (as if it stood M metres away from where it is).

This is not a feature for real fleets: ``python -m agent --sensor-fault`` is named and
documented as a test tool, and the agent logs a warning when it is set.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

KINDS = ("rotate", "scale", "shift")
HELP = "test tool: corrupt this robot's own record: rotate:DEG | scale:F | shift:M"


@dataclass(frozen=True)
class SensorFault:
    """One injected fault (module docstring): ``kind`` and its ``amount`` (deg, factor, m)."""

    kind: str
    amount: float

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"sensor fault kind must be one of {KINDS}, got {self.kind!r}")
        if not math.isfinite(self.amount):
            raise ValueError(f"sensor fault amount must be finite, got {self.amount}")
        if self.kind == "scale" and not 0.1 <= self.amount <= 10.0:
            raise ValueError(f"scale factor must be in [0.1, 10], got {self.amount}")
        if self.kind == "rotate" and not -360.0 <= self.amount <= 360.0:
            raise ValueError(f"rotation must be in [-360, 360] degrees, got {self.amount}")
        if self.kind == "shift" and not -5.0 <= self.amount <= 5.0:
            raise ValueError(f"shift must be in [-5, 5] m, got {self.amount}")

    @classmethod
    def parse(cls, text: str) -> SensorFault:
        """``rotate:40``, ``scale:1.4`` or ``shift:0.5``; ``ValueError`` otherwise."""
        kind, sep, raw = text.partition(":")
        if not sep or not raw:
            raise ValueError(f"sensor fault {text!r}: expected KIND:AMOUNT, KIND one of {KINDS}")
        try:
            amount = float(raw)
        except ValueError:
            raise ValueError(f"sensor fault {text!r}: {raw!r} is not a number") from None
        return cls(kind, amount)

    def __str__(self) -> str:
        return f"{self.kind}:{self.amount:g}"

    def apply(self, points: np.ndarray, orientations: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The corrupted ``(points (k, 2), orientations (k,))`` of a record (fixed frame)."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        ori = np.asarray(orientations, dtype=np.float64).reshape(-1)
        if ori.size not in (0, len(pts)):
            raise ValueError(f"{ori.size} orientations for {len(pts)} points")
        if self.kind == "rotate":
            a = math.radians(self.amount)
            c, s = math.cos(a), math.sin(a)
            rot = np.array([[c, -s], [s, c]])
            return pts @ rot.T, ori.copy()
        if self.kind == "scale":
            return pts * self.amount, ori.copy()
        return pts + np.array([self.amount, 0.0]), ori.copy()
