"""The NAO's numbers have one home (agent/core/nao.py), and sim and agent agree on them.

``sim/`` reaches agent.core.nao through agent.wire; the few sim modules that keep a copy
(the body model and locomotion, owned elsewhere) are pinned equal here, and the two
camera models (sim's renderer, the agent's angle model) must put a point on the same
pixel column.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from agent import wire as protocol
from agent.core import nao
from agent.core.perception import detector
from agent.core.perception.camera import CameraModel
from sim.camera import camera as sim_camera
from sim.physics import locomotion, nao_model


def test_sim_reaches_the_same_module_through_the_protocol() -> None:
    assert protocol.nao is nao
    assert protocol.HEAD_YAW_LIMIT == nao.HEAD_YAW_LIMIT == math.radians(119.5)
    assert detector.HEAD_YAW_LIMIT == nao.HEAD_YAW_LIMIT
    assert sim_camera.YAW_LIMIT == nao.HEAD_YAW_LIMIT


def test_camera_constants_agree() -> None:
    cm = CameraModel()
    assert (sim_camera.WIDTH, sim_camera.HEIGHT) == (cm.width, cm.height) == (640, 480)
    assert sim_camera.HFOV == cm.hfov == nao.CAMERA_HFOV == math.radians(60.9)
    assert pytest.approx(cm.fx, abs=1e-9) == sim_camera.FX
    # sim derives the vertical FOV from square pixels; the datasheet's 47.6° agrees
    assert math.degrees(sim_camera.VFOV) == pytest.approx(math.degrees(cm.vfov), abs=0.05)
    assert sim_camera.PITCH == -cm.pitch == nao.CAMERA_PITCH_DOWN
    assert sim_camera.CAMERA_Z == cm.height_m == nao.CAMERA_HEIGHT_M
    assert sim_camera.CAMERA_FORWARD == cm.cam_forward == nao.CAMERA_FORWARD


def test_copies_in_the_body_model_and_locomotion_are_pinned() -> None:
    assert nao_model.CAMERA_Z == nao.CAMERA_HEIGHT_M
    assert nao_model.CAMERA_FORWARD == nao.CAMERA_FORWARD
    assert locomotion.WALK_SPEED == nao.WALK_SPEED
    assert locomotion.BACK_SPEED == nao.BACK_SPEED


@pytest.mark.parametrize("bearing_deg", [-28.0, -15.0, 0.0, 9.0, 27.0])
def test_the_renderer_and_the_angle_model_put_a_point_on_the_same_column(
    bearing_deg: float,
) -> None:
    """A point at camera height, bearing β from the optical centre, 2 m away."""
    cm = CameraModel()
    b = math.radians(bearing_deg)
    eye, _, _ = sim_camera.camera_pose(0.0, 0.0, 0.0, 0.0)
    p = eye + 2.0 * np.array([math.cos(b), math.sin(b), 0.0])
    u = sim_camera.project(0.0, 0.0, 0.0, 0.0, p[None, :])[0, 0]
    # within 0.1 px: the agent's column model leaves out the 1.2° pitch (0.06 px at 28°)
    assert u == pytest.approx(cm.bearing_column(b), abs=0.1)
    assert cm.pixel_bearing(u) == pytest.approx(b, abs=2e-4)
