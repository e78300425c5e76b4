"""The rendered NAO against the camera model (sim/world.py, sim/camera.py, sim/nao_model.py)."""

from __future__ import annotations

import math
from collections.abc import Iterator

import cv2
import numpy as np
import pytest

from sim import camera
from sim.nao_model import BODY_PARTS, HEAD_PARTS, NECK_Z
from sim.scenarios import RobotSpec, Scenario, generate
from sim.world import World

NORTH = math.pi / 2


def orange_blobs(img: np.ndarray, min_area: int = 30) -> list[tuple[float, float, int]]:
    """(cx, cy, area) of the detector's orange components, largest first."""
    hsv = cv2.cvtColor(img, cv2.COLOR_BGR2HSV)
    mask = cv2.inRange(hsv, (2, 170, 50), (10, 255, 255))
    n, _, stats, cents = cv2.connectedComponentsWithStats(mask)
    out = [
        (float(cents[i][0]), float(cents[i][1]), int(stats[i][4]))
        for i in range(1, n)
        if stats[i][4] >= min_area
    ]
    return sorted(out, key=lambda b: -b[2])


@pytest.fixture(scope="module")
def world() -> Iterator[World]:
    sc = Scenario(robots=(RobotSpec(1, 0.0, 0.0), RobotSpec(2, 0.0, 0.6)), seed=3)
    with World(sc) as w:
        yield w


def test_image_shape_and_type(world: World) -> None:
    img = world.render(1, 0.0)
    assert img.shape == (480, 640, 3)
    assert img.dtype == np.uint8


def _part_centre(name: str, x: float, y: float, heading: float) -> np.ndarray:
    c, s = math.cos(heading), math.sin(heading)
    for p in BODY_PARTS:
        if p.name == name:
            px, py, pz = p.pos
            return np.array([x + c * px - s * py, y + s * px + c * py, pz])
    for p in HEAD_PARTS:
        if p.name == name:
            px, py, pz = p.pos
            return np.array([x + c * px - s * py, y + s * px + c * py, NECK_Z + pz])
    raise KeyError(name)


@pytest.mark.parametrize("theta_deg", [0.0, 180.0])
def test_front_and_back_show_three_blobs_where_the_model_predicts(
    world: World, theta_deg: float
) -> None:
    # Observer at the origin facing north; NAO 2 at 0.6 m ahead with relative
    # orientation theta (0: seen from behind, 180: faces the observer).
    heading = NORTH + math.radians(theta_deg)
    world.set_pose(1, 0.0, 0.0, NORTH)
    world.set_pose(2, 0.0, 0.6, heading)
    world.set_head_yaw(2, 0.0)
    blobs = orange_blobs(world.render(1, 0.0))
    assert len(blobs) == 3
    # Shoulders: the two lower blobs, left to right, against the projected centres of the
    # two covers (sorted by u). Seen straight from the front or back, what shows is the
    # cover's face nearest to the observer, 0.04 m (its half depth) nearer than its
    # centre: its centre is the blob's centroid. Tolerance 3 px (about 3 mm at 0.6 m)
    # horizontally, 6 px vertically (the camera, 4 cm higher, also sees the top face).
    shoulders = sorted((b for b in blobs if b[1] > 200), key=lambda b: b[0])
    assert len(shoulders) == 2
    pts = np.array([_part_centre(n, 0.0, 0.6, heading) for n in ("shoulder_l", "shoulder_r")])
    pts[:, 1] -= 0.04
    predicted = sorted(camera.project(0.0, 0.0, NORTH, 0.0, pts).tolist())
    for blob, uv in zip(shoulders, predicted, strict=True):
        assert abs(blob[0] - uv[0]) < 3.0
        assert abs(blob[1] - uv[1]) < 6.0
    head = [b for b in blobs if b[1] < 200]
    assert len(head) == 1
    assert abs(head[0][0] - 320.0) < 3.0


@pytest.mark.parametrize("theta_deg", [90.0, 270.0])
def test_side_view_shows_two_blobs(world: World, theta_deg: float) -> None:
    world.set_pose(1, 0.0, 0.0, NORTH)
    world.set_pose(2, 0.0, 0.6, NORTH + math.radians(theta_deg))
    world.set_head_yaw(2, 0.0)
    assert len(orange_blobs(world.render(1, 0.0))) == 2


def test_appearance_changes_with_orientation(world: World) -> None:
    world.set_pose(1, 0.0, 0.0, NORTH)
    masks = []
    for theta in (0.0, 60.0, 120.0, 180.0):
        world.set_pose(2, 0.0, 0.6, NORTH + math.radians(theta))
        hsv = cv2.cvtColor(world.render(1, 0.0), cv2.COLOR_BGR2HSV)
        masks.append(cv2.inRange(hsv, (2, 170, 50), (10, 255, 255)) > 0)
    for i in range(len(masks)):
        for j in range(i + 1, len(masks)):
            assert (masks[i] ^ masks[j]).sum() > 500


def test_room_has_no_orange_and_many_features() -> None:
    with World(generate(1, seed=11)) as w:
        orb = cv2.ORB.create(500)
        for yaw in (-2.0, -1.0, 0.0, 1.0, 2.0):
            img = w.render(1, yaw)
            hsv = cv2.cvtColor(img, cv2.COLOR_BGR2HSV)
            assert cv2.inRange(hsv, (2, 170, 50), (10, 255, 255)).sum() == 0
            assert len(orb.detect(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY), None)) >= 300


def test_head_yaw_out_of_range_is_an_error(world: World) -> None:
    with pytest.raises(ValueError, match="outside"):
        world.render(1, math.radians(120.0))
    with pytest.raises(ValueError, match="finite"):
        world.render(1, math.nan)


def test_unknown_robot_is_an_error(world: World) -> None:
    with pytest.raises(ValueError, match="unknown robot"):
        world.render(99, 0.0)
    with pytest.raises(ValueError, match="unknown robot"):
        world.pose(99)


def test_set_pose_is_read_back(world: World) -> None:
    world.set_pose(2, 0.25, -0.5, 3.0 * math.pi)
    x, y, th = world.pose(2)
    assert (x, y) == (0.25, -0.5)
    assert th == pytest.approx(-math.pi)
    with pytest.raises(ValueError, match="finite"):
        world.set_pose(2, math.inf, 0.0, 0.0)


def test_head_turned_robot_looks_different(world: World) -> None:
    world.set_pose(1, 0.0, 0.0, NORTH)
    world.set_pose(2, 0.0, 0.6, NORTH + math.pi)
    world.set_head_yaw(2, 0.0)
    a = world.render(1, 0.0)
    world.set_head_yaw(2, math.radians(90.0))
    b = world.render(1, 0.0)
    world.set_head_yaw(2, 0.0)
    assert np.abs(a.astype(int) - b.astype(int)).sum() > 0
