"""The agent's camera feed for viewers (agent/phases/camera_feed.py): thumbnails,
boxes in thumbnail pixels, the rate limit, failures that never reach the phases, and
the ``--publish-camera`` switch (off: nothing of it on the bus)."""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator

import cv2
import numpy as np
import pytest

from agent.__main__ import parse_args
from agent.adapters import FormationAdapter, PerceptionAdapter
from agent.body.zenoh_world import ZenohBody
from agent.config import AgentConfig
from agent.core.perception.detector import Detection
from agent.net.bus import Bus, BusConfig
from agent.phases.camera_feed import (
    CameraFeed,
    scale_box,
    thumbnail_detections,
    thumbnail_size,
)
from agent.phases.reporting import Phase
from agent.phases.runner import Runner
from agent.wire import MAX_CAMERA_DETECTIONS, CameraMsg, Message, decode, encode

IMAGE = np.zeros((480, 640, 3), np.uint8)
IMAGE[200:300, 100:200] = (0, 128, 255)  # an orange patch


def detection(box: tuple[int, int, int, int], d: float = 1.2, phi: float = 0.2) -> Detection:
    return Detection(
        distance=d, bearing=phi, confidence=0.9, orientation=0.0, scale=1.0, box=box, side=False
    )


class FakePerception(PerceptionAdapter):
    """The real adapter, with the detector's answer fixed (no mask bases loaded)."""

    def __init__(self, dets: list[Detection]) -> None:
        self.dets = dets
        self.calls = 0

    def detect(self, image: np.ndarray, yaw: float) -> list[Detection]:
        self.calls += 1
        return list(self.dets)


class Recorder:
    def __init__(self, fail: bool = False) -> None:
        self.sent: list[tuple[str, bytes, str]] = []
        self.fail = fail

    def publish(self, key: str, msg: Message, category: str = "") -> int:
        if self.fail:
            raise RuntimeError("link down")
        data = encode(msg)
        self.sent.append((key, data, category))
        return len(data)


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_thumbnail_size_keeps_the_aspect_ratio() -> None:
    assert thumbnail_size(640, 480) == (160, 120)
    assert thumbnail_size(320, 240) == (160, 120)
    assert thumbnail_size(1280, 720) == (160, 90)
    assert thumbnail_size(100, 10_000) == (160, 240)  # at most twice the target height
    with pytest.raises(ValueError, match="0x480"):
        thumbnail_size(0, 480)


def test_boxes_scale_to_the_thumbnail_and_stay_inside() -> None:
    src, dst = (640, 480), (160, 120)
    assert scale_box((100, 200, 100, 100), src, dst) == (25, 50, 25, 25)
    assert scale_box((1, 1, 2, 2), src, dst) == (0, 0, 1, 1)  # covers, never vanishes
    assert scale_box((600, 440, 100, 100), src, dst) == (150, 110, 10, 10)  # clipped
    assert scale_box((-10, -10, 20, 20), src, dst) == (0, 0, 3, 3)


def test_detections_are_numbered_bounded_and_finite() -> None:
    dets = [detection((4 * k, 0, 8, 8), d=0.5 + k) for k in range(MAX_CAMERA_DETECTIONS + 4)]
    dets[1] = detection((0, 0, 8, 8), d=math.nan)
    out = thumbnail_detections(dets, (640, 480), (160, 120))
    assert len(out) == MAX_CAMERA_DETECTIONS
    assert [d.id for d in out[:3]] == [0, 2, 3]  # the detector's numbers; nan left out
    assert out[0].box == (0, 0, 2, 2) and out[0].d == 0.5
    far = thumbnail_detections([detection((0, 0, 8, 8), d=1e6, phi=-9.0)], (640, 480), (160, 120))
    assert (far[0].d, far[0].phi) == (100.0, -2 * math.pi)


def test_a_published_frame_is_a_small_jpeg_with_its_detections() -> None:
    bus, clock = Recorder(), Clock()
    inner = FakePerception([detection((100, 200, 100, 100), d=1.25, phi=0.3)])
    feed = CameraFeed(inner, bus, 7, t_sim=lambda: 12.5, clock=clock)
    assert feed.detect(IMAGE, 0.4) == inner.dets  # the phases get the inner answer
    ((key, data, category),) = bus.sent
    assert key == "nao/7/camera" and category == "camera"
    msg = decode(data, expect=CameraMsg)
    assert (msg.robot, msg.seq, msg.t_sim, msg.width, msg.height) == (7, 0, 12.5, 160, 120)
    assert msg.yaw == pytest.approx(0.4)
    assert [(d.id, d.box, d.d, d.phi) for d in msg.detections] == [(0, (25, 50, 25, 25), 1.25, 0.3)]
    img = cv2.imdecode(np.frombuffer(msg.jpeg, np.uint8), cv2.IMREAD_COLOR)
    assert img.shape == (120, 160, 3)
    assert tuple(int(c) for c in img[62, 37]) == pytest.approx((0, 128, 255), abs=12)
    assert len(data) < 4000  # a 160x120 JPEG at quality 70


def test_the_rate_limit_bounds_the_frames_per_second() -> None:
    bus, clock = Recorder(), Clock()
    inner = FakePerception([])
    feed = CameraFeed(inner, bus, 2, t_sim=lambda: 0.0, clock=clock, max_rate=2.0)
    sent_at = []
    for k in range(40):  # 40 frames over 4 s, one every 0.1 s
        clock.t = 100.0 + k / 10
        if feed.offer(IMAGE, 0.0, []):
            sent_at.append(clock.t)
    assert len(sent_at) == 8 and feed.skipped == 32
    assert all(b - a >= 0.5 - 1e-9 for a, b in itertools.pairwise(sent_at))
    assert [decode(d).seq for _, d, _ in bus.sent] == list(range(8))
    with pytest.raises(ValueError, match="max_rate"):
        CameraFeed(inner, bus, 2, t_sim=lambda: 0.0, max_rate=0.0)
    with pytest.raises(ValueError, match="quality"):
        CameraFeed(inner, bus, 2, t_sim=lambda: 0.0, quality=0)


def test_a_frame_that_cannot_go_out_never_stops_the_robot() -> None:
    bus, clock = Recorder(fail=True), Clock()
    inner = FakePerception([detection((0, 0, 8, 8))])
    feed = CameraFeed(inner, bus, 2, t_sim=lambda: 0.0, clock=clock)
    assert feed.detect(IMAGE, 0.0) == inner.dets
    assert feed.failed == 1 and feed.published == 0
    bus.fail = False  # the next frame is tried at once: a failure spends no rate
    assert feed.offer(IMAGE, 0.0, [])
    # an image the encoder refuses, and a yaw outside the head's range (clipped)
    clock.t += 1.0
    assert not feed.offer(np.zeros((0, 0, 3), np.uint8), 0.0, [])
    assert feed.failed == 2
    clock.t += 1.0
    assert feed.offer(IMAGE, 2.5, []) and decode(bus.sent[-1][1]).yaw < 2.09


@pytest.fixture(scope="module")
def perception() -> PerceptionAdapter:
    return PerceptionAdapter()


@pytest.fixture()
def bus() -> Iterator[Bus]:
    b = Bus(BusConfig(multicast_scouting=False))
    try:
        yield b
    finally:
        b.close()


def test_off_by_default_nothing_of_the_feed_is_on_the_bus(
    bus: Bus, perception: PerceptionAdapter
) -> None:
    assert parse_args(["--id", "3"]).publish_camera is False
    assert AgentConfig(robot_id=3).publish_camera is False
    r = Runner(bus, ZenohBody(bus, 3), AgentConfig(robot_id=3), perception, FormationAdapter())
    assert r.ctx.perception is perception
    r.ctx.perception.detect(IMAGE, 0.0)
    r.ctx.report.status(Phase.SEARCH, 0.0, force=True)
    assert set(bus.stats.published_count) == {"status"}
    assert not any(k.endswith("/camera") for k in bus._publishers)


def test_publish_camera_wraps_the_perception_of_every_phase(
    bus: Bus, perception: PerceptionAdapter
) -> None:
    assert parse_args(["--id", "3", "--publish-camera"]).publish_camera is True
    cfg = AgentConfig(robot_id=3, publish_camera=True)
    r = Runner(bus, ZenohBody(bus, 3), cfg, perception, FormationAdapter())
    feed = r.ctx.perception
    assert isinstance(feed, CameraFeed) and feed.inner is perception
    assert r.search.ctx.perception is feed and r.hold.ctx.perception is feed
    assert feed.detect(IMAGE, 0.0) == perception.detect(IMAGE, 0.0)
    feed.detect(IMAGE, 0.0)  # within the rate limit's interval: not published
    assert bus.stats.published_count["camera"] == 1 and feed.skipped == 1
    assert "nao/3/camera" in bus._publishers
    assert 0 < bus.stats.published_bytes["camera"] < 4000
