"""The world in a look (sim/physics/world.py with sim/camera/look.py, sim/camera/picture.py):
the default look draws today's pictures bit for bit, a recolour reaches both renderers and
survives the culling, the scenario carries the look to render workers, which draw the same pictures."""

from __future__ import annotations

import hashlib
import math
import queue
from dataclasses import replace

import cv2
import numpy as np
import pytest

from agent.wire.picture import picture_of
from sim import scenarios
from sim.camera.look import Look
from sim.camera.picture import Shot
from sim.physics.world import World
from sim.scenarios import RobotSpec, Scenario
from sim.server.render_pool import Job, RenderPool, Result
from tests.sim.camera.test_renderer import _need_egl

NORTH = math.pi / 2
#: sha256 of four pictures of ``_golden_world`` drawn before looks existed (commit
#: e868236), per renderer: the default look must not change a bit of them.
GOLDEN = {
    "tiny": "f301644334ed1b1593edecbc484b09cff6427783b4d370e289d61f49bcdd9bb4",
    "egl": "eee92a4bbb38b04baadab08faa16b3871a7b94d323b8ff4bd20fb0ead6ef15b5",
}
#: The detector's orange (OpenCV HSV, docs/world.md "The model").
ORANGE_LO, ORANGE_HI = (2, 170, 50), (10, 255, 255)


def _pictures_digest(world: World) -> str:
    h = hashlib.sha256()
    for rid, yaw in ((1, 0.0), (1, 0.6), (2, -0.4), (3, 0.0)):
        h.update(world.render(rid, yaw).tobytes())
    return h.hexdigest()


@pytest.mark.parametrize("renderer", ["tiny", "egl"])
def test_the_default_look_draws_todays_pictures_bit_for_bit(renderer: str) -> None:
    if renderer == "egl":
        _need_egl()
    sc = scenarios.generate(3, 5, clutter=1)
    assert sc.look.is_default()
    with World(sc, noise=False, renderer=renderer) as w:
        assert _pictures_digest(w) == GOLDEN[renderer]
    spelled = replace(sc, look=Look.parse("default"))
    with World(spelled, noise=False, renderer=renderer) as w:
        assert _pictures_digest(w) == GOLDEN[renderer]


def _facing_pair(look: Look) -> Scenario:
    return Scenario(
        robots=(RobotSpec(1, 0.0, 0.0, NORTH), RobotSpec(2, 0.0, 1.0, -NORTH)), seed=3, look=look
    )


def _orange_and_teal(img: np.ndarray) -> tuple[int, int]:
    hsv = cv2.cvtColor(img, cv2.COLOR_BGR2HSV)
    orange = int((cv2.inRange(hsv, ORANGE_LO, ORANGE_HI) > 0).sum())
    teal = int((cv2.inRange(hsv, (80, 120, 50), (100, 255, 255)) > 0).sum())
    return orange, teal


@pytest.mark.parametrize("renderer", ["tiny", "egl"])
def test_teal_caps_take_the_orange_away_from_the_detector(renderer: str) -> None:
    if renderer == "egl":
        _need_egl()
    with World(_facing_pair(Look()), noise=False, renderer=renderer) as w:
        orange, _ = _orange_and_teal(w.render(1, 0.0))
    assert orange > 500  # caps and shoulders of NAO-j
    with World(_facing_pair(Look.parse("teal-caps")), noise=False, renderer=renderer) as w:
        first = _orange_and_teal(w.render(1, 0.0))
        w.render(1, math.radians(110.0))  # NAO-j out of view: culled (made transparent)
        again = _orange_and_teal(w.render(1, 0.0))  # and drawn again, still teal
    for orange, teal in (first, again):
        assert orange < 20 and teal > 500


def test_a_look_develops_the_worlds_pictures() -> None:
    with World(_facing_pair(Look()), noise=False) as w:
        plain = w.render(1, 0.0)
    dim = _facing_pair(Look.parse("light:0.5,warm:0.5,noise:3,seed:2"))
    with World(dim, noise=False) as w:
        a = w.render(1, 0.0)
    with World(dim, noise=False) as w:
        b = w.render(1, 0.0)
        c = w.render(1, 0.0)  # the next frame: other noise
    assert np.array_equal(a, b) and not np.array_equal(b, c)
    assert a.mean() < 0.7 * plain.mean()
    assert a[..., 2].mean() > a[..., 0].mean() + 10  # warm: red over blue


def test_shots_number_each_robots_pictures_and_its_head_turns() -> None:
    with World(_facing_pair(Look()), noise=False) as w:
        assert w.next_shot(1, 0.5) == Shot(1, 0, 0.5)
        assert w.next_shot(1, 0.5) == Shot(1, 1, 0.0)
        assert w.next_shot(2, -0.2) == Shot(2, 0, -0.2)
        w.render(1, 0.1)
        assert w.next_shot(1, 0.1) == Shot(1, 3, 0.0)
        with pytest.raises(ValueError, match="outside"):
            w.next_shot(1, 3.0)


def test_the_scenario_carries_its_look() -> None:
    sc = _facing_pair(Look.parse("noisy,hue:20"))
    d = scenarios.to_dict(sc)
    assert d["look"] == str(sc.look)
    assert scenarios.from_dict(d) == sc
    assert "look" not in scenarios.to_dict(_facing_pair(Look()))  # files as they were
    with pytest.raises(ValueError, match="unknown key 'shine'"):
        scenarios.from_dict({**d, "look": "shine:1"})
    with pytest.raises(ValueError, match="not a SPEC string"):
        scenarios.from_dict({**d, "look": 3})
    with pytest.raises(ValueError, match="is not a Look"):
        Scenario(robots=sc.robots, look="noisy")  # type: ignore[arg-type]


def test_render_workers_develop_the_worlds_look() -> None:
    """A pool worker builds its room from the scenario (with its look) and develops each
    picture as the shot the world numbered: the world's picture, bit for bit."""
    sc = _facing_pair(Look.parse("teal-caps,noisy,light:0.8,exposure:auto"))
    results: queue.Queue[Result] = queue.Queue()
    pool = RenderPool(sc, 1, results.put)
    try:
        poses = {1: (0.0, 0.0, NORTH), 2: (0.0, 1.0, -NORTH)}
        shots = [Shot(1, 0, 0.0), Shot(1, 1, 0.3), Shot(1, 2, -0.3)]
        yaws = [0.0, 0.3, 0.0]
        jobs = [Job(k, 1, y, poses, {2: 0.0}, s) for k, (y, s) in enumerate(zip(yaws, shots))]
        for job in jobs:
            pool.submit(job)
        got: dict[int, bytes] = {}
        while len(got) < len(jobs):
            res = results.get(timeout=120.0)
            pool.worker_done(res)
            assert res.error == ""
            got[res.job_id] = res.data
    finally:
        pool.close()
    with World(sc, noise=False) as w:
        for job in jobs:
            want = w.render(1, job.yaw, job.shot)
            img = picture_of("bgr8", 640, 480, got[job.job_id])
            assert np.array_equal(img, want)


@pytest.mark.parametrize("hue", [0.0, 167.0, -90.0])
def test_the_room_keeps_clear_of_the_caps_colour_whatever_the_look(hue: float) -> None:
    """No texel of the room falls in the caps' colour band, turned with them by the look
    (the NAO paper's premise: the caps are the only things of their colour in view), nor in
    the orange's."""
    from sim.physics.world import GUARD_HI, GUARD_LO, make_texture

    turn = round(hue / 2.0) % 180
    tex = make_texture(np.random.default_rng(7), 768, 512, turn)
    hsv = cv2.cvtColor(tex, cv2.COLOR_BGR2HSV)
    rel = ((hsv[..., 0].astype(int) - turn) % 180).astype(np.uint8)
    rel_hsv = np.dstack([rel, hsv[..., 1], hsv[..., 2]])
    assert not cv2.inRange(rel_hsv, GUARD_LO, GUARD_HI).any()
    assert not cv2.inRange(rel_hsv, (170, 110, 40), (180, 255, 255)).any()
    assert not cv2.inRange(hsv, GUARD_LO, GUARD_HI).any()
    # the texture is as rich in saturated colour as the orange caps' room
    assert np.mean(hsv[..., 1] >= 110) > 0.05
