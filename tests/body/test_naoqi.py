"""The NAOqi body and the virtual NAOs beyond the shared contract.

Raw qi clients check that the virtual NAO speaks the NAOqi API (names, signatures,
limits), and the NAOqi body's own duties: wake up and stand, turn qi errors into
``BodyError``, go through the world loop, and leave the process cleanly.
"""

from __future__ import annotations

import math
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import qi

from agent.body.base import BodyError
from agent.core.nao import COLORSPACE_BGR, HEAD_YAW_LIMIT, RESOLUTION_VGA, TOP_CAMERA
from tests.body.conftest import FACING, Rig, rig

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def nao() -> Iterator[Rig]:
    with rig("naoqi", FACING) as r:
        yield r


@pytest.fixture()
def client(nao: Rig) -> Iterator[qi.Session]:
    s = qi.Session()
    s.connect(nao.urls[2])
    try:
        yield s
    finally:
        s.close()


def test_one_service_directory_per_robot_on_its_own_port(nao: Rig) -> None:
    assert sorted(nao.urls) == [1, 2]
    ports = {u.rsplit(":", 1)[1] for u in nao.urls.values()}
    assert len(ports) == 2
    s = qi.Session()
    s.connect(nao.urls[1])
    try:
        names = {str(info["name"]) for info in s.services()}
        assert {"ALMotion", "ALVideoDevice", "ALRobotPosture"} <= names
    finally:
        s.close()


def test_the_body_wakes_the_robot_and_stands_it(nao: Rig, client: qi.Session) -> None:
    motion, posture = client.service("ALMotion"), client.service("ALRobotPosture")
    motion.rest()
    assert motion.robotIsWakeUp() is False
    with pytest.raises(RuntimeError, match="not awake"):
        motion.moveTo(0.1, 0.0, 0.0)
    nao.make(2)
    assert motion.robotIsWakeUp() is True
    assert posture.getPosture() == "StandInit"


def test_head_joint_stops_at_its_limits(client: qi.Session) -> None:
    motion = client.service("ALMotion")
    motion.setAngles("HeadYaw", 3.0, 0.3)
    assert motion.getAngles("HeadYaw", True)[0] == pytest.approx(HEAD_YAW_LIMIT, abs=1e-6)
    motion.setAngles(["HeadYaw"], [-0.25], 0.3)
    assert motion.getAngles(["HeadYaw"], True) == pytest.approx([-0.25], abs=1e-6)
    with pytest.raises(RuntimeError, match="HeadYaw only"):
        motion.setAngles("LShoulderPitch", 0.1, 0.3)


def test_video_device_serves_the_top_camera_in_bgr_vga(nao: Rig, client: qi.Session) -> None:
    video = client.service("ALVideoDevice")
    with pytest.raises(RuntimeError, match="kVGA"):
        video.subscribeCamera("t", TOP_CAMERA, 1, COLORSPACE_BGR, 5)
    with pytest.raises(RuntimeError, match="top camera"):
        video.subscribeCamera("t", 1, RESOLUTION_VGA, COLORSPACE_BGR, 5)
    h = video.subscribeCamera("t", TOP_CAMERA, RESOLUTION_VGA, COLORSPACE_BGR, 5)
    before = nao.server.counts["camera"]
    img = video.getImageRemote(h)
    assert img[:4] == (640, 480, 3, COLORSPACE_BGR)
    assert isinstance(img[6], bytearray) and len(img[6]) == 640 * 480 * 3
    assert img[8] == pytest.approx(math.radians(60.9) / 2, abs=1e-6)
    end = time.monotonic() + 5.0  # the loop counts a request once its reply is out
    while nao.server.counts["camera"] == before and time.monotonic() < end:
        time.sleep(0.01)
    assert nao.server.counts["camera"] == before + 1  # rendered by the world loop
    assert video.unsubscribe(h) is True
    with pytest.raises(RuntimeError, match="unknown handle"):
        video.getImageRemote(h)


def test_qi_errors_become_body_errors(nao: Rig, client: qi.Session) -> None:
    body = nao.make(2)
    motion = client.service("ALMotion")
    motion.rest()  # someone else put the robot to rest: ALMotion refuses to walk
    try:
        with pytest.raises(BodyError, match=r"walk \(ALMotion.moveTo\).*not awake"):
            body.walk(0.1)
    finally:
        motion.wakeUp()
    assert body.walk(0.1).status == "done" and body.walk(-0.1).status == "done"


def test_the_world_going_away_is_a_body_error() -> None:
    with rig("naoqi", FACING) as r:
        body = r.make(1)
        assert body.camera(0.0).image.shape == (480, 640, 3)
        r.gateway.close()
        time.sleep(0.2)
        with pytest.raises(BodyError):
            body.camera(0.0)


def test_an_agent_process_exits_cleanly_with_a_live_session(nao: Rig) -> None:
    """No close by the caller: the body closes its session at exit (a qi session left to
    the interpreter's finalisation can end the process with "terminate called...")."""
    code = (
        "from agent.body.naoqi import NaoqiBody\n"
        f"b = NaoqiBody({nao.urls[1]!r}, 1)\n"
        "print(b.camera(0.1).yaw)\n"
    )
    res = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60
    )
    assert res.returncode == 0, res.stderr[-2000:]
    assert float(res.stdout.split()[-1]) == pytest.approx(0.1, abs=1e-6)
    assert "terminate called" not in res.stderr
