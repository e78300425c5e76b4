import math

import numpy as np
import pytest

from agent.core.perception.camera import CameraModel
from agent.core.perception.dbase import DBase, Fit
from agent.core.perception.detector import Detector
from tests.perception.synth import canvas, draw_nao, synthetic_mbase

CAM = CameraModel(cam_forward=0.05)
HR = CAM.cy + CAM.fy * math.tan(CAM.pitch)


@pytest.fixture(scope="module")
def det() -> Detector:
    mb = synthetic_mbase(list(range(0, 360, 15)), HR)
    db = DBase([Fit(0.6, 0.0, 1.0, 0.0, 20)] * len(mb), mb.digest())
    return Detector(mb, db, CAM)


def test_centred_nao_distance_and_bearing(det: Detector) -> None:
    img = canvas()
    draw_nao(img, 320, HR - 40 * 0.5, 0.5, 0.0)  # r_g = 0.5 → 1.2 m from the camera
    (d,) = det.detect(img, 0.0)
    assert d.distance == pytest.approx(1.25, abs=0.03)  # + 5 cm camera offset
    assert d.bearing == pytest.approx(0.0, abs=math.radians(0.5))
    assert d.confidence > 0.9 and not d.side
    x, y, w, h = d.box
    assert x < 320 < x + w and y < HR < y + h


def test_head_yaw_adds_to_the_bearing(det: Detector) -> None:
    img = canvas()
    draw_nao(img, 320, HR - 40 * 0.5, 0.5, 0.0)
    (d,) = det.detect(img, math.radians(60))
    # camera at (0.025, 0.043) looking at 60°: the target at 1.2 m from it
    px = 0.05 * math.cos(math.radians(60)) + 1.2 * math.cos(math.radians(60))
    py = 0.05 * math.sin(math.radians(60)) + 1.2 * math.sin(math.radians(60))
    assert d.bearing == pytest.approx(math.atan2(py, px), abs=math.radians(0.5))
    assert d.distance == pytest.approx(math.hypot(px, py), abs=0.03)


def test_off_centre_nao_bearing_from_pixel_offset(det: Detector) -> None:
    img = canvas()
    u = CAM.bearing_column(math.radians(20))
    draw_nao(img, u, HR - 40 * 0.5, 0.5, 0.0)
    (d,) = det.detect(img, 0.0)
    b = math.radians(20)  # seen from the camera, 5 cm ahead of the body centre
    expect = math.atan2(1.2 * math.sin(b), 0.05 + 1.2 * math.cos(b))
    assert d.bearing == pytest.approx(expect, abs=math.radians(1.0))


def test_images_without_naos(det: Detector) -> None:
    assert det.detect(np.zeros((480, 640, 3), np.uint8), 0.0) == []  # black
    assert det.detect(canvas(), 0.0) == []  # no orange
    img = canvas()
    img[100:140, 100:400] = (0, 60, 255)  # an orange bar
    assert det.detect(img, 0.0) == []


@pytest.mark.parametrize(
    ("img", "msg"),
    [
        (np.zeros((0, 0, 3), np.uint8), "empty"),
        (np.zeros((4, 4, 3), np.uint8), "too small"),
        (np.zeros((480, 641, 3), np.uint8), "expects 640x480"),
        (np.zeros((480, 640), np.uint8), r"\(h, w, 3\)"),
        (np.zeros((480, 640, 4), np.uint8), r"\(h, w, 3\)"),
        (np.zeros((480, 640, 3), np.float64), "uint8"),
        (None, "numpy array"),
    ],
)
def test_bad_images_raise_clear_errors(det: Detector, img: object, msg: str) -> None:
    with pytest.raises(ValueError, match=msg):
        det.detect(img, 0.0)  # type: ignore[arg-type]


def test_bad_head_yaw_and_construction(det: Detector) -> None:
    with pytest.raises(ValueError, match=r"119\.5"):
        det.detect(canvas(), math.radians(120))
    with pytest.raises(ValueError, match="finite"):
        det.detect(canvas(), float("nan"))
    with pytest.raises(ValueError, match="digest"):
        Detector(det.mbase, DBase([Fit(0.6, 0, 1, 0, 3)] * len(det.mbase), "x"), CAM)
    with pytest.raises(ValueError, match="entries"):
        Detector(det.mbase, DBase([Fit(0.6, 0, 1, 0, 3)], det.mbase.digest()), CAM)
    with pytest.raises(ValueError, match="threshold"):
        Detector(det.mbase, det.dbase, CAM, threshold=1.5)


def test_nao_cut_by_the_image_border_is_not_reported(det: Detector) -> None:
    img = canvas()
    draw_nao(img, 60, HR - 40 * 0.5, 0.5, 0.0)  # left shoulder cut by the border
    assert det.detect(img, 0.0) == []
    img = canvas()
    draw_nao(img, 120, HR - 40 * 0.5, 0.5, 0.0)  # wholly inside
    assert len(det.detect(img, 0.0)) == 1
