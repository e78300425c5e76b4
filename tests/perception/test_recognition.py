import math

import numpy as np
import pytest

from agent.core.perception.camera import CameraModel
from agent.core.perception.recognition import (
    candidate_groups,
    fast_scores,
    group_crop,
    recognise,
    reference_scores,
    share_gap,
)
from agent.core.perception.segmentation import extract_tuples
from tests.perception.synth import draw_nao_mask, synthetic_mbase

CAM = CameraModel()
HR = CAM.cy + CAM.fy * math.tan(CAM.pitch)
DEGS = list(range(0, 360, 15))


@pytest.fixture(scope="module")
def mb():  # type: ignore[no-untyped-def]
    return synthetic_mbase(DEGS, HR)


def scene(items: list[tuple[float, float, float]]) -> tuple[np.ndarray, list]:
    """Binary image with drawn NAOs (cx, scale, theta_deg) standing on the same floor."""
    m = np.zeros((480, 640), np.uint8)
    for cx, s, th in items:
        draw_nao_mask(m, cx, HR - 40 * s, s, math.radians(th))
    return extract_tuples(m)


def test_single_nao_found_with_its_mask_and_scale(mb) -> None:  # type: ignore[no-untyped-def]
    labels, tuples = scene([(320, 0.6, 30)])
    out = recognise(labels, tuples, mb, HR)
    assert len(out) == 1
    m = out[0]
    assert m.confidence > 0.9
    assert DEGS[m.mask] % 180 in (15, 30, 45)  # front/back ambiguity of a silhouette
    assert m.scale == pytest.approx(0.6, abs=0.03)


def test_several_naos_each_found(mb) -> None:  # type: ignore[no-untyped-def]
    labels, tuples = scene([(110, 0.45, 0), (330, 0.7, 60), (540, 0.5, 90)])
    out = recognise(labels, tuples, mb, HR)
    assert len(out) == 3
    used = [i for m in out for i in m.tuples]
    assert len(used) == len(set(used))
    centres = sorted(m.box[0] + m.box[2] / 2 for m in out)
    assert centres == pytest.approx([110, 330, 540], abs=12)


def test_clutter_blobs_are_rejected(mb) -> None:  # type: ignore[no-untyped-def]
    m = np.zeros((480, 640), np.uint8)
    m[200:260, 100:300] = 255  # a big orange box
    m[210:230, 400:420] = 255
    m[240:250, 450:470] = 255
    m[215:235, 500:520] = 255
    labels, tuples = extract_tuples(m)
    assert recognise(labels, tuples, mb, HR) == []


def test_group_far_below_horizon_is_not_a_candidate(mb) -> None:  # type: ignore[no-untyped-def]
    m = np.zeros((480, 640), np.uint8)
    draw_nao_mask(m, 320, 380, 0.5, 0.0)  # a "NAO" lying on the floor in front
    _labels, tuples = extract_tuples(m)
    assert candidate_groups(tuples, mb, HR) == []


@pytest.mark.parametrize(
    ("scale", "theta"), [(0.45, 0), (0.6, 20), (0.8, 75), (1.1, 140), (0.5, 265)]
)
def test_fast_search_equals_algorithm_1(mb, scale: float, theta: float) -> None:  # type: ignore[no-untyped-def]
    """The vectorised search gives Algorithm 1's answer: same best mask (or one the
    reference scores equally), λ and r_g within small tolerances."""
    labels, tuples = scene([(320, scale, theta)])
    group = tuple(range(len(tuples)))
    crop = group_crop(labels, tuples, group)
    lam_f, rg_f = fast_scores([crop], mb)
    ok = mb.n_tuples == len(group)
    ref = [reference_scores(crop, mb, k) if ok[k] else (0.0, 0.0) for k in range(len(mb))]
    lam_r = np.array([r[0] for r in ref])
    lam_f = np.where(ok, lam_f[0], 0.0)
    kf, kr = int(np.argmax(lam_f)), int(np.argmax(lam_r))
    assert lam_r[kf] >= lam_r[kr] - 0.02
    assert lam_f[kf] == pytest.approx(lam_r[kr], abs=0.04)
    assert rg_f[0, kf] == pytest.approx(ref[kf][1], abs=0.011)
    # and the ranking of masks agrees where it matters (all clear matches)
    assert np.corrcoef(lam_f[ok], lam_r[ok])[0, 1] > 0.9


def test_bad_inputs(mb) -> None:  # type: ignore[no-untyped-def]
    labels, tuples = scene([(320, 0.6, 0)])
    with pytest.raises(ValueError, match="threshold"):
        recognise(labels, tuples, mb, HR, threshold=0.0)
    with pytest.raises(ValueError, match="mask index"):
        reference_scores(np.ones((5, 5), np.uint8), mb, len(mb))
    with pytest.raises(ValueError, match="crop"):
        reference_scores(np.ones((0, 5), np.uint8), mb, 0)
    with pytest.raises(ValueError, match="crop 0"):
        fast_scores([np.ones((0,), np.uint8)], mb)
    assert recognise(labels, [], mb, HR) == []


def test_share_gap_separates_naos_from_uneven_clutter(mb) -> None:  # type: ignore[no-untyped-def]
    _labels, tuples = scene([(320, 0.6, 0)])
    group = tuple(range(len(tuples)))
    k = DEGS.index(0)
    assert share_gap(tuples, group, mb, k) < 0.1
    m = np.zeros((480, 640), np.uint8)
    m[200:250, 300:350] = 255  # one big cube and two small ones
    m[205:213, 380:388] = 255
    m[240:247, 260:267] = 255
    _, cubes = extract_tuples(m)
    assert share_gap(cubes, (0, 1, 2), mb, k) > 0.5
    assert share_gap(cubes, (0, 1), mb, k) == 1.0  # tuple counts differ


def test_nao_floating_above_its_place_is_rejected(mb) -> None:  # type: ignore[no-untyped-def]
    """The camera's height and pitch fix where a NAO's top is at a given scale."""
    m = np.zeros((480, 640), np.uint8)
    draw_nao_mask(m, 320, HR - 40 * 0.3 - 25, 0.3, 0.0)  # 25 px too high at r_g 0.3
    labels, tuples = extract_tuples(m)
    assert recognise(labels, tuples, mb, HR) == []
    m[:] = 0
    draw_nao_mask(m, 320, HR - 40 * 0.3, 0.3, 0.0)
    labels, tuples = extract_tuples(m)
    assert len(recognise(labels, tuples, mb, HR)) == 1


def test_far_nao_at_small_scale_is_found(mb) -> None:  # type: ignore[no-untyped-def]
    """r_g down to 0.15 is searched (about 3.5 m with the sim's NAO)."""
    labels, tuples = scene([(320, 0.2, 0)])
    (m,) = recognise(labels, tuples, mb, HR)
    assert m.scale == pytest.approx(0.2, abs=0.02)
