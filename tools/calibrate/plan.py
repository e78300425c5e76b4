"""The views a calibration takes (NAO paper 3.1.2, 5.2.1, 5.2.2 (i)): where NAO-j stands,
how it is turned, where both heads look.

NAO-i (the observer) stands still; NAO-j (the subject) stands at ``distance`` m (body centre
to body centre) at ``bearing`` from NAO-i's heading (0: straight ahead, +90°: to its left).
A person places NAO-j there facing NAO-i (orientation 180°); NAO-j then turns itself on
the spot through the placement's orientations, in increasing order, and turns its own head
for the ``head`` views. The orientation of a view is the paper's relative orientation:
NAO-j's heading minus NAO-i's line of sight to it (0°: NAO-j shows its back).

Three sets of views:

- ``mbase``: at d_s = 0.6 m straight ahead, every ``step_deg`` (the paper's 72 masks, 5°
  apart); every ``head_every_deg`` also with NAO-j's head at ``head_yaws_deg``; and the
  side postures (NAO-i's head at ±90°, NAO-j there side-on, Figure 20's set-up);
- ``dbase``: the same kinds of view at ``distances`` (the paper's 20 in 0.5-1.45 m and on
  to 3.1 m), every ``dbase_step_deg``; the ``mbase`` views count as the d_s samples;
- ``check``: held out, at ``check_distances`` and orientations between the masks', NAO-i's
  head turned a little (NAO-j off the image centre), and a few views with nothing in
  sight (NAO-i looking away) for the precision.

Views are grouped by placement (one prompt each) in the order of the sets.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any

from agent.core.perception.camera import CameraModel
from tools.calibrate.distances import DISTANCES

SETS = ("mbase", "dbase", "check")
VIEW_KINDS = ("main", "head", "side", "none")
FACING_DEG = 180.0  # how a person places NAO-j: facing NAO-i
HALF_WIDTH = 0.25  # m, NAO's half-width with a margin (keeps check views whole in the image)
NEGATIVE_YAW_DEG = 105.0  # NAO-i's head for the views with nothing in sight
CHECK_DISTANCES = (0.55, 0.85, 1.25, 1.75, 2.25, 2.75, 2.95)


@dataclass(frozen=True)
class Shot:
    """One view: NAO-j's placement, its orientation and head yaw, NAO-i's head yaw (deg)."""

    id: str
    set: str
    kind: str
    distance: float
    bearing_deg: float
    orientation_deg: float
    observer_yaw_deg: float
    subject_yaw_deg: float = 0.0

    @property
    def placement(self) -> tuple[str, float, float]:
        return (self.set, self.distance, self.bearing_deg)


def _grid(step: float, offset: float = 0.0) -> tuple[float, ...]:
    n = round(360.0 / step)
    return tuple(round((offset + i * step) % 360.0, 6) for i in range(n))


def turning_order(orientations: list[float]) -> list[float]:
    """Orientations in the order NAO-j reaches them turning left from facing NAO-i."""
    return sorted(orientations, key=lambda o: ((o - FACING_DEG) % 360.0, o))


@dataclass(frozen=True)
class PlanSpec:
    """The grid of a calibration (defaults: the paper's, and a held-out check)."""

    step_deg: float = 5.0
    d_s: float = 0.6
    head_every_deg: float = 30.0
    head_yaws_deg: tuple[float, ...] = (-90.0, -45.0, 45.0, 90.0)
    side: bool = True
    distances: tuple[float, ...] = DISTANCES
    dbase_step_deg: float = 5.0
    dbase_poses: bool = True  # head and side views at every distance too
    check_distances: tuple[float, ...] = CHECK_DISTANCES
    check_step_deg: float = 20.0
    check_offset_deg: float = 2.5
    check_yaw_deg: float = 20.0
    negatives: int = 4

    def __post_init__(self) -> None:
        for name in ("step_deg", "dbase_step_deg", "check_step_deg", "head_every_deg"):
            v = getattr(self, name)
            if not (0.5 <= v <= 360.0) or abs(360.0 / v - round(360.0 / v)) > 1e-6:
                raise ValueError(f"{name} {v} must divide 360° (and be >= 0.5°)")
        for name in ("head_yaws_deg", "distances", "check_distances"):
            object.__setattr__(self, name, tuple(float(v) for v in getattr(self, name)))
        if not 0.4 <= self.d_s <= 2.0:
            raise ValueError(f"d_s {self.d_s} m outside [0.4, 2] m")
        for d in (*self.distances, *self.check_distances):
            if not 0.4 <= d <= 3.5:
                raise ValueError(f"distance {d} m outside [0.4, 3.5] m")
        if len(set(self.distances)) < 3 and self.distances:
            raise ValueError("eq. 6 needs at least 3 distinct distances")
        if any(abs(y) > 119.5 for y in self.head_yaws_deg) or not 0 <= self.check_yaw_deg <= 60:
            raise ValueError("head yaws must be within ±119.5°, the check's within 60°")
        if not 0 <= self.negatives <= 100:
            raise ValueError(f"negatives {self.negatives} outside [0, 100]")

    def to_dict(self) -> dict[str, Any]:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> PlanSpec:
        names = {f.name for f in fields(cls)}
        unknown = set(doc) - names
        if unknown:
            raise ValueError(f"unknown plan fields {sorted(unknown)}")
        args: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in doc.items()}
        return cls(**args)

    def shots(self, camera: CameraModel | None = None) -> list[Shot]:
        """Every view, grouped by placement, in capture order; ids are stable."""
        cam = CameraModel() if camera is None else camera
        out: list[Shot] = []

        def add(set_: str, kind: str, d: float, b: float, o: float, oy: float, sy: float) -> None:
            out.append(Shot(f"{set_[0]}{len(out):05d}", set_, kind, d, b, o, oy, sy))

        def poses(set_: str, d: float, step: float, extra: bool) -> None:
            """Main (and head) views ahead, then the side views left and right."""
            heads = set(_grid(self.head_every_deg)) if extra else set()
            for o in turning_order(list(_grid(step))):
                add(set_, "main", d, 0.0, o, 0.0, 0.0)
                if o in heads:
                    for hy in self.head_yaws_deg:
                        add(set_, "head", d, 0.0, o, 0.0, hy)
            if extra and self.side:
                for b in (90.0, -90.0):
                    for o in turning_order([90.0, 270.0]):
                        add(set_, "side", d, b, o, b, 0.0)

        poses("mbase", self.d_s, self.step_deg, True)
        same = set(_grid(self.dbase_step_deg)) <= set(_grid(self.step_deg))
        for d in self.distances:
            if not (same and abs(d - self.d_s) < 1e-9):
                poses("dbase", d, self.dbase_step_deg, self.dbase_poses)
        for i, d in enumerate(self.check_distances):
            room = math.degrees(cam.hfov / 2 - math.atan(HALF_WIDTH / d)) - 2.0
            y = max(0.0, min(self.check_yaw_deg, room))
            yaws = (0.0, y, -y)
            for j, o in enumerate(
                turning_order(list(_grid(self.check_step_deg, self.check_offset_deg)))
            ):
                add("check", "main", d, 0.0, o, yaws[j % 3], 0.0)
            if i == 0:
                for k in range(self.negatives):
                    yaw = NEGATIVE_YAW_DEG * (1 if k % 2 == 0 else -1)
                    add("check", "none", d, 0.0, FACING_DEG, yaw, 0.0)
        return out


def coarse() -> PlanSpec:
    """A small grid for rehearsals and tests: 8 masks, 6 distances, a few check views."""
    return PlanSpec(
        step_deg=45.0,
        head_every_deg=90.0,
        head_yaws_deg=(-45.0, 45.0),
        side=False,
        distances=(0.5, 0.8, 1.2, 1.8, 2.4, 3.1),
        dbase_step_deg=45.0,
        dbase_poses=False,
        check_distances=(0.7, 1.5, 2.8),
        check_step_deg=90.0,
        check_offset_deg=0.0,
        negatives=2,
    )
