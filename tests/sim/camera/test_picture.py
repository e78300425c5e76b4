"""Pictures developed in a look (sim/camera/picture.py): each step on synthetic pictures."""

from __future__ import annotations

import numpy as np
import pytest

from sim.camera.look import Look
from sim.camera.picture import AE_GAIN_MAX, LUMA_BGR, Shot, develop, exposure_gain, smear

SHOT = Shot(robot_id=1, frame=0, turned=0.0)


def _picture(seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.integers(30, 200, size=(48, 64, 3), dtype=np.uint8)


def test_the_default_look_returns_the_picture_itself() -> None:
    img = _picture()
    assert develop(img, Look(), SHOT) is img
    moved = Shot(1, 5, 0.4)
    assert develop(img, Look(hue=40.0, sat=0.5), moved) is img  # a recolour is the scene's


def test_light_and_warmth_scale_the_channels() -> None:
    img = np.full((4, 4, 3), 100, dtype=np.uint8)
    assert (develop(img, Look(light=0.5), SHOT) == 50).all()
    b, g, r = develop(img, Look(warm=1.0), SHOT)[0, 0]
    assert (b, g, r) == (70, 100, 130)
    b, g, r = develop(img, Look(warm=-0.5), SHOT)[0, 0]
    assert (b, g, r) == (115, 100, 85)
    assert (develop(img, Look(light=4.0), SHOT) == 255).all()  # clipped at 8 bits
    out = develop(img, Look(light=0.5), SHOT)
    assert out.dtype == np.uint8 and out.flags.c_contiguous


def test_blur_only_after_the_head_turned_and_along_its_motion() -> None:
    img = np.zeros((3, 20, 3), dtype=np.uint8)
    img[:, 10] = 200  # one bright column
    look = Look(blur=4)
    assert (develop(img, look, Shot(1, 1, 0.0)) == img).all()  # the head did not move
    left = develop(img, look, Shot(1, 1, +0.3))  # turned left: each pixel sees to its right
    assert list(np.flatnonzero(left[0, :, 0])) == [7, 8, 9, 10]
    right = develop(img, look, Shot(1, 1, -0.3))
    assert list(np.flatnonzero(right[0, :, 0])) == [10, 11, 12, 13]
    assert left[0, 8, 0] == right[0, 12, 0] == 50  # the column spread over 4 pixels


def test_smear_keeps_a_flat_picture_flat_to_the_borders() -> None:
    img = np.full((2, 9, 3), 77.0, dtype=np.float32)
    for direction in (1, -1):
        assert np.allclose(smear(img, 5, direction), 77.0)


def test_auto_exposure_brings_the_mean_to_its_target() -> None:
    dim = (_picture() // 3).astype(np.uint8)
    out = develop(dim, Look(exposure=100.0), SHOT)
    assert float((out.reshape(-1, 3) @ LUMA_BGR).mean()) == pytest.approx(100.0, abs=1.5)
    bright = develop(_picture(), Look(light=2.0, exposure=100.0), SHOT)
    assert float((bright.reshape(-1, 3) @ LUMA_BGR).mean()) == pytest.approx(100.0, abs=1.5)
    black = np.zeros((4, 4, 3), dtype=np.float32)
    assert exposure_gain(black, 100.0) == AE_GAIN_MAX  # a black picture: the most gain
    assert exposure_gain(np.full((4, 4, 3), 1.0, np.float32), 100.0) == AE_GAIN_MAX


def test_noise_is_seeded_per_scenario_look_robot_and_frame() -> None:
    img = np.full((48, 64, 3), 120, dtype=np.uint8)
    look = Look(noise=5.0)
    a = develop(img, look, Shot(1, 3), seed=7)
    assert (a == develop(img, look, Shot(1, 3), seed=7)).all()  # deterministic
    assert float(a.astype(float).std()) == pytest.approx(5.0, rel=0.1)
    for other in (
        develop(img, look, Shot(1, 4), seed=7),  # next frame
        develop(img, look, Shot(2, 3), seed=7),  # another robot
        develop(img, look, Shot(1, 3), seed=8),  # another scenario
        develop(img, Look(noise=5.0, seed=1), Shot(1, 3), seed=7),  # another look seed
    ):
        assert not (other == a).all()
