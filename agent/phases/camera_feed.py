"""Camera frames for viewers (docs/design.md §10 "Seeing the fleet").

With ``--publish-camera`` an agent publishes, on its own key ``nao/{id}/camera``, a small
JPEG of the frames it analyses with what the detector found in them (NAO paper §3:
distance by eq. 6, bearing by eq. 3), so that a viewer sees what each robot sees. Off by
default: without the flag nothing of this module runs and the bus carries exactly what
it carried before.

:class:`CameraFeed` is a :class:`~agent.seams.Perception` around the agent's own: every
call goes to the inner perception unchanged; :meth:`CameraFeed.detect` also offers the
frame to the feed. So every phase that looks (search sweeps, hold, march, safe steps,
re-search) feeds the viewers, and none of them knows. Bounded: at most
:data:`MAX_RATE` frames a second (the frames in between are not even encoded), each a
:data:`THUMBNAIL` JPEG at quality :data:`JPEG_QUALITY` (3-8 kB), at most
``MAX_THUMBNAIL_BYTES`` (a bigger one is dropped); a frame that cannot be encoded or
published is counted and logged (rate limited), never raised into the robot's phases.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Sequence
from typing import Protocol

import cv2
import numpy as np

from agent.core.nao import HEAD_YAW_LIMIT
from agent.core.perception.compass import CompassResult
from agent.core.perception.detector import Detection
from agent.core.perception.obstacles import ObstacleDetection
from agent.seams import Neighbours, Perception, Sightings
from agent.wire import (
    MAX_CAMERA_DETECTIONS,
    MAX_THUMBNAIL_BYTES,
    CameraDetection,
    CameraMsg,
    Guard,
    Message,
    key_camera_feed,
)

log = logging.getLogger("agent.phases.camera_feed")

#: Frames published per second at most: 2 x ~5 kB, ~10 kB/s a robot (docs/agent.md).
MAX_RATE = 2.0
#: The thumbnail's width and height (px) for the NAO's 4:3 camera; other aspect ratios
#: keep the width.
THUMBNAIL = (160, 120)
JPEG_QUALITY = 70
#: The bearings and distances a thumbnail's detection may carry (CameraDetection's bounds).
MAX_D = 100.0
MAX_PHI = 2.0 * math.pi


class Publisher(Protocol):
    """What the feed publishes with (:class:`agent.net.bus.Bus`)."""

    def publish(self, key: str, msg: Message, category: str = "") -> int: ...


def thumbnail_size(width: int, height: int, target: tuple[int, int] = THUMBNAIL) -> tuple[int, int]:
    """The thumbnail's (width, height) for an image of ``width`` x ``height``: the target
    width, the image's aspect ratio, at least 1 px and at most twice the target height."""
    if width < 1 or height < 1:
        raise ValueError(f"image of {width}x{height} pixels")
    w = target[0]
    h = max(1, min(2 * target[1], round(w * height / width)))
    return w, h


def scale_box(
    box: Sequence[int], src: tuple[int, int], dst: tuple[int, int]
) -> tuple[int, int, int, int]:
    """``box`` (x, y, w, h) of an image of size ``src`` (w, h) in the pixels of its
    thumbnail of size ``dst``: the smallest box covering it, clipped to the thumbnail."""
    x, y, w, h = (float(v) for v in box)
    sx, sy = dst[0] / src[0], dst[1] / src[1]
    x0 = min(dst[0], max(0, math.floor(x * sx)))
    y0 = min(dst[1], max(0, math.floor(y * sy)))
    x1 = min(dst[0], max(x0, math.ceil((x + w) * sx)))
    y1 = min(dst[1], max(y0, math.ceil((y + h) * sy)))
    return x0, y0, x1 - x0, y1 - y0


def thumbnail_detections(
    dets: Sequence[Detection], src: tuple[int, int], dst: tuple[int, int]
) -> tuple[CameraDetection, ...]:
    """The first ``MAX_CAMERA_DETECTIONS`` detections with a finite distance and bearing,
    numbered in the detector's order, boxes in thumbnail pixels."""
    out: list[CameraDetection] = []
    for k, d in enumerate(dets):
        if len(out) == MAX_CAMERA_DETECTIONS:
            break
        if not (math.isfinite(d.distance) and math.isfinite(d.bearing)):
            continue
        out.append(
            CameraDetection(
                id=k,
                box=scale_box(d.box, src, dst),
                d=min(MAX_D, max(0.0, float(d.distance))),
                phi=min(MAX_PHI, max(-MAX_PHI, float(d.bearing))),
            )
        )
    return tuple(out)


def encode_jpeg(image: np.ndarray, size: tuple[int, int], quality: int = JPEG_QUALITY) -> bytes:
    """A JPEG of ``image`` (BGR or grey uint8) shrunk to ``size`` (w, h)."""
    small = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
    ok, buf = cv2.imencode(".jpg", small, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise ValueError("OpenCV could not encode the thumbnail as JPEG")
    return bytes(buf.tobytes())


class CameraFeed:
    """The agent's perception, publishing the frames it analyses (module docstring).

    ``t_sim``: the robot's time now (the body's); ``clock``: the agent's clock for the
    rate limit. Counts: ``published``, ``skipped`` (rate limit), ``failed``.
    """

    def __init__(
        self,
        inner: Perception,
        bus: Publisher,
        robot_id: int,
        t_sim: Callable[[], float],
        clock: Callable[[], float] = time.monotonic,
        max_rate: float = MAX_RATE,
        quality: int = JPEG_QUALITY,
    ) -> None:
        if not (math.isfinite(max_rate) and max_rate > 0.0):
            raise ValueError(f"max_rate must be > 0 frames/s, got {max_rate}")
        if not 1 <= quality <= 100:
            raise ValueError(f"JPEG quality must be in [1, 100], got {quality}")
        self.inner = inner
        self.bus = bus
        self.key = key_camera_feed(robot_id)
        self.robot_id = robot_id
        self.t_sim = t_sim
        self.clock = clock
        self.interval = 1.0 / max_rate
        self.quality = quality
        self.next_at = -math.inf
        self.published = 0
        self.skipped = 0
        self.failed = 0
        self.guard = Guard(log.warning, burst=3, per_second=0.1)

    # ----------------------------------------------------------------- the feed

    def offer(self, image: np.ndarray, yaw: float, dets: Sequence[Detection]) -> bool:
        """Publish this frame unless one went out less than ``1 / max_rate`` s ago;
        True when it was published."""
        now = self.clock()
        if now < self.next_at:
            self.skipped += 1
            return False
        try:
            self.bus.publish(self.key, self.frame(image, yaw, dets), "camera")
        except Exception as exc:  # a viewer's frame never costs the robot its run
            self.failed += 1
            self.guard.reject(f"camera frame {self.published}", exc)
            return False
        self.next_at = now + self.interval
        self.published += 1
        return True

    def frame(self, image: np.ndarray, yaw: float, dets: Sequence[Detection]) -> CameraMsg:
        """The message of one frame: thumbnail, detections, yaw and the robot's time."""
        h, w = image.shape[:2]
        size = thumbnail_size(w, h)
        jpeg = encode_jpeg(image, size, self.quality)
        if len(jpeg) > MAX_THUMBNAIL_BYTES:
            raise ValueError(f"thumbnail of {len(jpeg)} bytes over {MAX_THUMBNAIL_BYTES}")
        return CameraMsg(
            robot=self.robot_id,
            seq=self.published,
            t_sim=max(0.0, float(self.t_sim())),
            width=size[0],
            height=size[1],
            jpeg=jpeg,
            yaw=min(HEAD_YAW_LIMIT, max(-HEAD_YAW_LIMIT, float(yaw))),
            detections=thumbnail_detections(dets, (w, h), size),
        )

    # ----------------------------------------------------------------- Perception

    def detect(self, image: np.ndarray, yaw: float) -> list[Detection]:
        dets = self.inner.detect(image, yaw)
        self.offer(image, yaw, dets)
        return dets

    def to_fixed(self, dets: list[Detection], heading: float) -> Sightings:
        return self.inner.to_fixed(dets, heading)

    def merge(self, sightings: list[Sightings]) -> Neighbours:
        return self.inner.merge(sightings)

    def measure_turn(self, before: np.ndarray, after: np.ndarray) -> CompassResult:
        return self.inner.measure_turn(before, after)

    def measure_walk(self, before: np.ndarray, after: np.ndarray) -> CompassResult:
        return self.inner.measure_walk(before, after)

    def detect_obstacles(self, image: np.ndarray, yaw: float) -> list[ObstacleDetection]:
        return self.inner.detect_obstacles(image, yaw)

    def obstacles_fixed(self, dets: list[ObstacleDetection], heading: float) -> np.ndarray:
        return self.inner.obstacles_fixed(dets, heading)

    def merge_obstacles(self, sightings: list[np.ndarray]) -> np.ndarray:
        return self.inner.merge_obstacles(sightings)
