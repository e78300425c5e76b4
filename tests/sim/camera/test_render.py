"""The rendered NAO against the camera model (sim/physics/world.py, sim/camera/camera.py,
sim/physics/nao_model.py)."""

from __future__ import annotations

import math
from collections.abc import Iterator

import cv2
import numpy as np
import pytest

from sim.camera import camera
from sim.physics.nao_model import BODY_PARTS, HEAD_PARTS, NECK_Z
from sim.physics.world import World
from sim.scenarios import RobotSpec, Scenario, generate

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


def _sphere_extremes(centre: np.ndarray, r: float) -> tuple[float, float, float]:
    """(min u, max u, min v) of a sphere's silhouette seen by robot 1 at the origin."""
    eye, _, _ = camera.camera_pose(0.0, 0.0, NORTH, 0.0)
    g = np.random.default_rng(0).normal(size=(20000, 3))
    pts = centre + r * g / np.linalg.norm(g, axis=1, keepdims=True)
    visible = np.einsum("ij,ij->i", pts - centre, eye - pts) >= 0
    uv = camera.project(0.0, 0.0, NORTH, 0.0, pts[visible])
    return float(uv[:, 0].min()), float(uv[:, 0].max()), float(uv[:, 1].min())


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
    img = world.render(1, 0.0)
    blobs = orange_blobs(img)
    assert len(blobs) == 3
    mask = cv2.inRange(cv2.cvtColor(img, cv2.COLOR_BGR2HSV), (2, 170, 50), (10, 255, 255))
    n, _, stats, _ = cv2.connectedComponentsWithStats(mask)
    boxes = sorted(
        (tuple(int(v) for v in stats[i][:4]) for i in range(1, n) if stats[i][4] >= 30),
        key=lambda b: b[0],
    )
    # Left to right: a shoulder, the head cap, the other shoulder. The shoulder covers
    # are spheres (r = 0.038 m); their outer side and top are not occluded, so the blob's
    # bounding box must meet the projected silhouette there. Tolerance 2 px (2 mm at 0.6 m).
    r = next(p.size[0] for p in BODY_PARTS if p.name == "shoulder_l")
    centres = sorted(
        (_part_centre(nm, 0.0, 0.6, heading) for nm in ("shoulder_l", "shoulder_r")),
        key=lambda c: float(c[0]),
    )
    left, right = (_sphere_extremes(c, r) for c in centres)
    lx, ly, _, _ = boxes[0]
    rx, ry, rw, _ = boxes[2]
    assert abs(lx - left[0]) < 2.0
    assert abs(ly - left[2]) < 2.0
    assert abs(rx + rw - right[1]) < 2.0
    assert abs(ry - right[2]) < 2.0
    # The head cap: centred, its top edge where the cap's top front edge projects.
    hx, hy, hw, _ = boxes[1]
    assert abs(hx + hw / 2 - 320.0) < 1.5
    cap = next(p for p in HEAD_PARTS if p.name == "cap")
    top_front = np.array([[0.0, 0.6 - cap.size[0], NECK_Z + cap.pos[2] + cap.size[2]]])
    v_top = camera.project(0.0, 0.0, NORTH, 0.0, top_front)[0, 1]
    assert abs(hy - v_top) < 2.0


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


def test_clutter_is_orange_and_light_varies() -> None:
    from sim.scenarios import ClutterSpec, LightSpec

    sc = Scenario(
        robots=(RobotSpec(1, 0.0, 0.0),),
        clutter=(ClutterSpec(0.0, 1.0, 0.45, 0.06),),
        light=LightSpec(intensity=0.6),
        seed=2,
    )
    with World(sc) as w:
        blobs = orange_blobs(w.render(1, 0.0))
        assert len(blobs) == 1
        uv = camera.project(0.0, 0.0, NORTH, 0.0, np.array([[0.0, 0.97, 0.45]]))[0]
        assert abs(blobs[0][0] - uv[0]) < 3.0 and abs(blobs[0][1] - uv[1]) < 3.0
        dim = w.render(1, 0.5).astype(float).mean()
    with World(Scenario(robots=sc.robots, seed=2)) as w:
        assert w.render(1, 0.5).astype(float).mean() > dim * 1.3


def test_culling_the_naos_out_of_view_leaves_every_picture_unchanged() -> None:
    """NAOs out of the camera's view are made transparent before a render
    (TinyRenderer skips them: ~16 % of a picture at 50 NAOs); the pictures are the same,
    pixel for pixel, as a world that draws every NAO, while robots move and heads turn."""
    sc = generate(20, 5)
    rng = np.random.default_rng(0)
    with World(sc) as culled, World(sc) as full:
        full._cull = lambda robot_id: None  # type: ignore[method-assign]
        hidden = 0
        for k in range(16):
            rid = int(rng.integers(1, 21))
            yaw = float(rng.uniform(-camera.YAW_LIMIT, camera.YAW_LIMIT))
            if k % 3 == 0:
                j = int(rng.integers(1, 21))
                x, y, h = culled.pose(j)
                for w in (culled, full):
                    w.set_pose(j, x + 0.05, y - 0.05, h + 0.4)
            a, b = culled.render(rid, yaw), full.render(rid, yaw)
            assert np.array_equal(a, b), (rid, yaw, int(np.sum(np.any(a != b, axis=2))))
            hidden = max(hidden, len(culled._hidden))
        assert hidden >= 5  # it did cull
