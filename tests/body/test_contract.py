"""The Body contract (agent/seams.py): the same tests for the world, zenoh and NAOqi bodies.

Robot 1 stands at the origin facing north; robot 2 stands 0.9 m ahead, facing it. The
tests run in file order on one world per body (the motions undo themselves; the contact
test comes last).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from agent.adapters import PerceptionAdapter
from agent.body.base import BodyError
from agent.core.nao import CAMERA_HEIGHT, CAMERA_WIDTH, HEAD_YAW_LIMIT, WALK_SPEED
from tests.body.conftest import Rig


@pytest.fixture(scope="module")
def perception() -> PerceptionAdapter:
    return PerceptionAdapter()


def test_identity_and_time(facing: Rig) -> None:
    body = facing.make(1)
    assert body.robot_id == 1
    assert body.t_sim >= 0.0


def test_camera_sees_the_robot_ahead(facing: Rig, perception: PerceptionAdapter) -> None:
    body = facing.make(1)
    f = body.camera(0.0)
    assert f.image.shape == (CAMERA_HEIGHT, CAMERA_WIDTH, 3) and f.image.dtype == np.uint8
    assert abs(f.yaw) < 1e-6 and f.t_sim >= 0.0
    dets = perception.detect(f.image, f.yaw)
    assert len(dets) == 1, dets
    assert dets[0].distance == pytest.approx(0.9, abs=0.12)
    assert abs(dets[0].bearing) < math.radians(3)


def test_camera_reports_the_yaw_applied(facing: Rig) -> None:
    body = facing.make(1)
    ahead = body.camera(0.0)
    left = body.camera(0.8)
    assert left.yaw == pytest.approx(0.8, abs=1e-5)
    assert facing.world.head_yaw(1) == pytest.approx(0.8, abs=1e-5)
    assert float(np.mean(np.abs(left.image.astype(int) - ahead.image.astype(int)))) > 5.0


@pytest.mark.parametrize("yaw", [HEAD_YAW_LIMIT, -HEAD_YAW_LIMIT])
def test_camera_at_the_head_limits(facing: Rig, yaw: float) -> None:
    f = facing.make(1).camera(yaw)
    assert f.yaw == pytest.approx(yaw, abs=1e-5) and abs(f.yaw) <= HEAD_YAW_LIMIT


@pytest.mark.parametrize("yaw", [HEAD_YAW_LIMIT + 0.01, -2.5, math.nan, math.inf])
def test_head_yaw_outside_the_limits_is_refused_before_moving(facing: Rig, yaw: float) -> None:
    body = facing.make(1)
    body.camera(0.3)
    with pytest.raises(ValueError, match="head yaw"):
        body.camera(yaw)
    assert facing.world.head_yaw(1) == pytest.approx(0.3, abs=1e-5)


def test_turn_and_back(facing: Rig) -> None:
    body = facing.make(1)
    t0 = body.camera(0.0).t_sim  # a fresh body has seen no robot time yet
    x0, y0, h0 = facing.world.pose(1)
    r = body.turn(0.5)
    assert r.status == "done" and r.t_sim > t0
    assert facing.world.pose(1)[2] == pytest.approx(h0 + 0.5, abs=1e-6)
    assert body.t_sim == pytest.approx(r.t_sim, abs=1e-3)
    assert body.turn(-0.5).status == "done"
    assert facing.world.pose(1) == pytest.approx((x0, y0, h0), abs=1e-6)


def test_walk_and_back(facing: Rig) -> None:
    body = facing.make(1)
    x0, y0, h0 = facing.world.pose(1)
    t0 = body.camera(0.0).t_sim
    r = body.walk(0.1)
    assert r.status == "done"
    assert r.t_sim - t0 == pytest.approx(0.1 / WALK_SPEED, abs=0.05)
    assert facing.world.pose(1)[1] == pytest.approx(y0 + 0.1, abs=1e-6)
    assert body.walk(-0.1).status == "done"
    assert facing.world.pose(1) == pytest.approx((x0, y0, h0), abs=1e-6)


def test_sidestep_and_back(facing: Rig) -> None:
    body = facing.make(1)
    x0, y0, h0 = facing.world.pose(1)
    r = body.side(0.1)  # facing north: to the left is west
    assert r.status == "done"
    assert facing.world.pose(1)[:2] == pytest.approx((x0 - 0.1, y0), abs=1e-6)
    assert body.side(-0.1).status == "done"
    assert facing.world.pose(1) == pytest.approx((x0, y0, h0), abs=1e-6)


@pytest.mark.parametrize("distance", [math.nan, 0.5])
def test_impossible_sidestep_is_refused_before_moving(facing: Rig, distance: float) -> None:
    body = facing.make(1)
    before = facing.world.pose(1)
    with pytest.raises(ValueError, match="sidestep"):
        body.side(distance)
    assert facing.world.pose(1) == before


@pytest.mark.parametrize("distance", [math.nan, 60.0])
def test_impossible_walk_is_refused_before_moving(facing: Rig, distance: float) -> None:
    body = facing.make(1)
    before = facing.world.pose(1)
    with pytest.raises(ValueError):
        body.walk(distance)
    assert facing.world.pose(1) == before


def test_stop_is_harmless_and_idempotent(facing: Rig) -> None:
    body = facing.make(1)
    body.stop()
    body.stop()
    assert body.camera(0.0).image.shape == (CAMERA_HEIGHT, CAMERA_WIDTH, 3)


def test_a_robot_the_world_lacks_is_a_body_error(facing: Rig) -> None:
    with pytest.raises(BodyError):
        facing.make(99).camera(0.0)


def test_close_is_idempotent_and_a_closed_connection_is_a_body_error(facing: Rig) -> None:
    body = facing.make(2)
    body.close()
    body.close()
    if facing.kind == "naoqi":  # the others' connection is the caller's (bus, world)
        with pytest.raises(BodyError, match="closed"):
            body.camera(0.0)


def test_walking_into_a_robot_is_a_contact(facing: Rig) -> None:
    body = facing.make(1)
    r = body.walk(0.8)
    assert r.status == "contact"
    y = facing.world.pose(1)[1]
    assert 0.4 < y < 0.7  # stopped at the other robot's footprint, not through it
    assert body.walk(-0.4).status == "done"  # moving away is allowed
