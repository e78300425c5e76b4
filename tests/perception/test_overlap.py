"""Splitting tuples merged by overlapping NAOs (agent/core/perception/overlap.py)."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from agent.core.perception.camera import CameraModel
from agent.core.perception.overlap import split_merged
from agent.core.perception.recognition import recognise
from agent.core.perception.segmentation import extract_tuples
from tests.perception.synth import draw_nao_mask, synthetic_mbase

CAM = CameraModel()
HR = CAM.cy + CAM.fy * math.tan(CAM.pitch)


def test_two_touching_discs_split_at_the_neck() -> None:
    m = np.zeros((120, 160), np.uint8)
    cv2.circle(m, (50, 60), 20, 255, -1)
    cv2.circle(m, (82, 60), 14, 255, -1)  # overlaps the first: one component
    labels, tuples = extract_tuples(m)
    assert len(tuples) == 1
    p = split_merged(labels, tuples)
    assert len(p.tuples) == 3  # the component and its two pieces
    assert p.parent == [0, 0, 0]
    big, small = sorted(p.tuples[1:], key=lambda t: -t.area)
    assert big.cx == pytest.approx(50, abs=3) and small.cx == pytest.approx(82, abs=3)
    assert big.area + small.area == tuples[0].area  # every pixel goes to one piece
    # the component's atoms are its pieces; the label image holds the pieces
    assert set(p.atoms[0]) >= {big.label, small.label}
    assert set(np.unique(p.labels[labels > 0])) <= set(p.atoms[0])


@pytest.mark.parametrize(
    "shape",
    ["disc", "ellipse", "band", "square"],
)
def test_compact_shapes_are_not_split(shape: str) -> None:
    m = np.zeros((120, 200), np.uint8)
    if shape == "disc":
        cv2.circle(m, (100, 60), 25, 255, -1)
    elif shape == "ellipse":
        cv2.ellipse(m, (100, 60), (40, 18), 0, 0, 360, 255, -1)
    elif shape == "band":
        m[50:58, 20:180] = 255
    else:
        m[30:90, 70:130] = 255
    labels, tuples = extract_tuples(m)
    p = split_merged(labels, tuples)
    assert len(p.tuples) == 1 and p.atoms == [(tuples[0].label,)] and p.parent == [0]
    assert np.array_equal(p.labels, labels)


def test_split_is_deterministic_and_validates() -> None:
    m = np.zeros((100, 200), np.uint8)
    cv2.circle(m, (60, 50), 18, 255, -1)
    cv2.circle(m, (90, 50), 15, 255, -1)
    labels, tuples = extract_tuples(m)
    a, b = split_merged(labels, tuples), split_merged(labels, tuples)
    assert a.tuples == b.tuples and np.array_equal(a.labels, b.labels)
    with pytest.raises(ValueError, match="2-D"):
        split_merged(np.zeros((3, 3, 3), np.int32), [])


def test_nao_in_front_of_another_both_recognised() -> None:
    """A far NAO whose shoulder touches a near NAO's shoulder in the image: without the
    split the merged blob spoils both groups; with it both are found at their scales."""
    mb = synthetic_mbase(list(range(0, 360, 15)), HR)
    m = np.zeros((480, 640), np.uint8)
    draw_nao_mask(m, 300, HR - 40 * 0.8, 0.8, 0.0)  # near, r_g 0.8
    draw_nao_mask(m, 474, HR - 40 * 0.45, 0.45, 0.0)  # far, its left shoulder on the other
    labels, tuples = extract_tuples(m)
    assert len(tuples) == 5  # two shoulders merged into one tuple
    p = split_merged(labels, tuples)
    out = recognise(p.labels, p.tuples, mb, HR, atoms=p.atoms, parent=p.parent)
    scales = sorted(round(x.scale, 2) for x in out)
    assert len(out) == 2
    assert scales[0] == pytest.approx(0.45, abs=0.04) and scales[1] == pytest.approx(0.8, abs=0.05)
    with pytest.raises(ValueError, match="atoms and parent"):
        recognise(p.labels, p.tuples, mb, HR, atoms=p.atoms)


def test_small_disc_half_inside_a_big_one_is_cut_at_the_concave_corners() -> None:
    """No neck (the small disc sits half inside the big one): the outline's two concave
    corners give the cut."""
    m = np.zeros((120, 200), np.uint8)
    cv2.circle(m, (90, 60), 30, 255, -1)
    cv2.circle(m, (124, 60), 11, 255, -1)
    labels, tuples = extract_tuples(m)
    p = split_merged(labels, tuples)
    assert len(p.tuples) == 3
    small = min(p.tuples[1:], key=lambda t: t.area)
    assert small.cx > 118 and 150 < small.area < 450


def test_group_keeping_part_of_its_own_split_cap_is_refused() -> None:
    from agent.core.perception.recognition import leaves_sibling_inside
    from agent.core.perception.segmentation import Tuple

    whole = Tuple(1, 50.0, 20.0, (20, 10, 60, 20), 900)
    left = Tuple(2, 35.0, 20.0, (20, 10, 30, 20), 450)
    right = Tuple(3, 65.0, 20.0, (50, 10, 30, 20), 450)
    shoulder = Tuple(4, 30.0, 50.0, (20, 40, 20, 20), 300)
    tuples, parent = [whole, shoulder, left, right], [0, 1, 0, 0]
    assert leaves_sibling_inside(tuples, (1, 2), parent, (20, 10, 70, 50))
    assert not leaves_sibling_inside(tuples, (1, 2), parent, (20, 10, 30, 50))
    assert not leaves_sibling_inside(tuples, (0, 1), parent, (20, 10, 70, 50))
