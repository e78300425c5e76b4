"""The forehead-camera model behind the angle model (NAO paper 3.2.2, Figure 10, eq. 3).

A pinhole camera (principal point at the image centre) on a head that yaws about a
vertical neck axis. The paper only uses tuple groups at the image centre, so the
relative angle is the head yaw alone (eq. 3). Here a detection need not be centred: its
pixel column gives the extra bearing ``atan((cx - u) / fx)`` (positive to the left).

To make the M-base masks (rendered at the image centre, 3.1.2) valid across the whole
field of view, the detector works in a *cylindrical* image: column ``u' = cx + fx*atan(x)``
and row ``v' = cy + fy*y/sqrt(1 + x^2)`` with ``x = (u - cx)/fx``, ``y = (v - cy)/fy``. A
rotation of the camera about the vertical axis is then a pure horizontal shift, so an
NAO at bearing β looks the same as one straight ahead, and ``β = (cx - u')/fx``. The
visual compass (3.2.1) uses the same property: a body turn is a column shift.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from agent.core import nao


@dataclass(frozen=True)
class CameraModel:
    """Intrinsics and mounting of the NAO forehead camera (docs/design.md §4).

    ``cam_forward`` is how far the optical centre sits ahead of the neck (head-yaw) axis
    and ``neck_forward`` how far the neck axis sits ahead of the body centre, both in
    metres; they turn a camera-relative sighting into a body-relative one.
    """

    width: int = nao.CAMERA_WIDTH
    height: int = nao.CAMERA_HEIGHT
    hfov: float = nao.CAMERA_HFOV
    vfov: float = nao.CAMERA_VFOV
    height_m: float = nao.CAMERA_HEIGHT_M
    pitch: float = -nao.CAMERA_PITCH_DOWN
    cam_forward: float = nao.CAMERA_FORWARD
    neck_forward: float = nao.NECK_FORWARD

    def __post_init__(self) -> None:
        if self.width < 16 or self.height < 16:
            raise ValueError(f"camera size {self.width}x{self.height} is too small (min 16x16)")
        for name in ("hfov", "vfov"):
            v = getattr(self, name)
            if not (0.0 < v < math.pi) or not math.isfinite(v):
                raise ValueError(f"camera {name} must be in (0, pi) rad, got {v}")

    @property
    def fx(self) -> float:
        return (self.width / 2.0) / math.tan(self.hfov / 2.0)

    @property
    def fy(self) -> float:
        return (self.height / 2.0) / math.tan(self.vfov / 2.0)

    @property
    def cx(self) -> float:
        return self.width / 2.0

    @property
    def cy(self) -> float:
        return self.height / 2.0

    def pixel_bearing(self, u: float) -> float:
        """Bearing (rad, +left) of image column ``u`` of the perspective image."""
        if not math.isfinite(u):
            raise ValueError(f"pixel column must be finite, got {u}")
        return math.atan2(self.cx - u, self.fx)

    def cyl_bearing(self, u_cyl: float) -> float:
        """Bearing (rad, +left) of column ``u_cyl`` of the cylindrical image."""
        if not math.isfinite(u_cyl):
            raise ValueError(f"pixel column must be finite, got {u_cyl}")
        return (self.cx - u_cyl) / self.fx

    def bearing_column(self, bearing: float) -> float:
        """The perspective-image column of a ray at ``bearing`` (rad, +left)."""
        if not abs(bearing) < math.pi / 2:
            raise ValueError(f"bearing {bearing} rad is behind the image plane")
        return self.cx - self.fx * math.tan(bearing)

    def cylindrical_maps(self) -> tuple[np.ndarray, np.ndarray]:
        """``cv2.remap`` maps (float32) that turn the perspective image into the cylindrical one.

        For every output pixel (u', v') they give the perspective source pixel (u, v).
        """
        uc = np.arange(self.width, dtype=np.float64)
        vc = np.arange(self.height, dtype=np.float64)
        ang = (uc - self.cx) / self.fx  # angle of each cylindrical column
        x = np.tan(np.clip(ang, -1.5, 1.5))
        y_cyl = (vc - self.cy) / self.fy
        map_x = np.broadcast_to(self.cx + self.fx * x, (self.height, self.width))
        map_y = self.cy + self.fy * y_cyl[:, None] * np.sqrt(1.0 + x[None, :] ** 2)
        return map_x.astype(np.float32), map_y.astype(np.float32)

    def body_offset(self, head_yaw: float) -> tuple[float, float]:
        """The optical centre in the body frame (x forward, y left) at ``head_yaw``."""
        return (
            self.neck_forward + self.cam_forward * math.cos(head_yaw),
            self.cam_forward * math.sin(head_yaw),
        )

    def sweep_yaws(
        self,
        min_distance: float = 0.5,
        half_width: float = 0.15,
        limit: float = nao.HEAD_YAW_LIMIT,
    ) -> tuple[float, ...]:
        """Evenly spaced head yaws over [-limit, limit] (rad) such that a NAO at least
        ``min_distance`` m away (half-width ``half_width`` m) is wholly inside at least one
        image: the step is at most hfov - 2·atan(half_width / min_distance).

        With the defaults: 10 yaws, 26.6° apart (the detector drops NAOs cut by the border).
        """
        if not (min_distance > half_width > 0 and 0 < limit < math.pi):
            raise ValueError(
                f"need min_distance > half_width > 0 and 0 < limit < pi, got "
                f"{min_distance}, {half_width}, {limit}"
            )
        step = self.hfov - 2.0 * math.atan(half_width / min_distance)
        if step <= 0:
            raise ValueError(f"a NAO at {min_distance} m does not fit in the image")
        n = max(2, math.ceil(2.0 * limit / step) + 1)
        return tuple(float(v) for v in np.linspace(-limit, limit, n))
