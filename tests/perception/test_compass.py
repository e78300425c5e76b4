import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.perception import compass as cp
from agent.core.perception.camera import CameraModel
from agent.core.perception.compass import VisualCompass
from tests.perception.synth import canvas, textured_panorama, view_of_panorama

CAM = CameraModel()


@pytest.fixture(scope="module")
def pano() -> np.ndarray:
    return textured_panorama(7, CAM.fx)


@pytest.mark.parametrize("step_deg", [-15.0, -5.0, 0.0, 7.5, 15.0])
def test_turn_measured_within_half_degree(pano: np.ndarray, step_deg: float) -> None:
    vc = VisualCompass(CAM)
    a = view_of_panorama(pano, 0.3, CAM.fx, CAM.fy)
    b = view_of_panorama(pano, 0.3 + math.radians(step_deg), CAM.fx, CAM.fy)
    r = vc.measure(a, b)
    assert r.ok, r.reason
    assert math.degrees(r.dtheta) == pytest.approx(step_deg, abs=0.5)
    assert r.inliers <= r.matches and 0.4 <= r.inlier_ratio <= 1.0


def test_featureless_view_fails_instead_of_guessing() -> None:
    r = VisualCompass(CAM).measure(canvas(), canvas())
    assert not r.ok and r.dtheta == 0.0 and "featureless" in r.reason


def test_step_beyond_the_field_of_view_fails(pano: np.ndarray) -> None:
    a = view_of_panorama(pano, 0.0, CAM.fx, CAM.fy)
    b = view_of_panorama(pano, math.radians(75), CAM.fx, CAM.fy)
    r = VisualCompass(CAM).measure(a, b)
    assert not r.ok and r.dtheta == 0.0 and r.reason


def test_views_of_different_rooms_fail_instead_of_guessing() -> None:
    """Disagreeing views (Figure 22): the same camera in two unrelated rooms, for the turn
    compass and for the walk compass's looser vote tolerance."""
    a = view_of_panorama(textured_panorama(7, CAM.fx), 0.3, CAM.fx, CAM.fy)
    b = view_of_panorama(textured_panorama(8, CAM.fx), 0.3, CAM.fx, CAM.fy)
    for vc in (VisualCompass(CAM), VisualCompass(CAM, tol=math.radians(1.0))):
        r = vc.measure(a, b)
        assert not r.ok and r.dtheta == 0.0 and r.reason


def test_bad_inputs(pano: np.ndarray) -> None:
    a = view_of_panorama(pano, 0.0, CAM.fx, CAM.fy)
    vc = VisualCompass(CAM)
    with pytest.raises(ValueError, match="expects 640x480"):
        vc.measure(a, a[:240, :320])
    with pytest.raises(ValueError, match=r"\(h, w, 3\)"):
        vc.measure(a[:, :, 0], a)
    with pytest.raises(ValueError, match="min_matches"):
        VisualCompass(CAM, min_matches=1)
    with pytest.raises(ValueError, match="ratio"):
        VisualCompass(CAM, min_inlier_ratio=0.0)
    for bad in ({"tol": 0.0}, {"max_dv": 0.0}, {"n_features": 0}):
        with pytest.raises(ValueError, match="> 0"):
            VisualCompass(CAM, **bad)  # type: ignore[arg-type]


# ------------------------------------------------------------ the same answers, cheaper
def _table(votes: np.ndarray, tol: float) -> np.ndarray:
    """The m×m table the counts stand for."""
    return (np.abs(votes[:, None] - votes[None, :]) <= tol).sum(axis=1)


@given(
    st.lists(st.integers(-40, 40), max_size=120),
    st.sampled_from([0.0, 1e-18, 1e-12]),
)
@settings(max_examples=300, deadline=None)
def test_inlier_counts_are_the_tables(ticks: list[int], jitter: float) -> None:
    """Votes on a grid of tol/7 (many at exactly tol apart, where rounding decides),
    nudged by ``jitter``: the sorted count is the table's, vote for vote."""
    tol = math.radians(0.4)
    votes = np.array(ticks, dtype=np.float64) * (tol / 7.0)
    votes = votes + jitter * np.where(np.arange(len(votes)) % 2 == 0, 1.0, -1.0)
    assert (cp._within(votes, tol) == _table(votes, tol)).all()


# ------------------------------------------------------------------ the guided match
def _brute(
    v_a: np.ndarray, d_a: np.ndarray, v_b: np.ndarray, d_b: np.ndarray, max_dv: float
) -> tuple[np.ndarray, np.ndarray]:
    """Every feature of ``before`` against every feature of ``after`` (numpy Hamming),
    restricted to its band; the two nearest by (distance, index); the ratio test."""
    dist = np.bitwise_count(d_a[:, None, :] ^ d_b[None, :, :]).sum(axis=2, dtype=np.int64)
    band = np.abs(v_b[None, :] - v_a[:, None]) <= max_dv
    qs, ts = [], []
    for i in range(len(v_a)):
        js = np.flatnonzero(band[i])
        if len(js) < 2:
            continue
        first, second = js[np.lexsort((js, dist[i, js]))][:2]
        if dist[i, first] < cp.RATIO * dist[i, second]:
            qs.append(i)
            ts.append(int(first))
    return np.array(qs, dtype=np.intp), np.array(ts, dtype=np.intp)


def _random_features(
    seed: int, n_a: int, n_b: int, width: int, rows: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Rows on a half-pixel grid (many exactly ``max_dv`` apart) and descriptors of
    ``width`` bytes, most of ``after``'s noisy copies of ``before``'s (near matches,
    and with few bytes many ties)."""
    rng = np.random.default_rng(seed)
    v_a = rng.integers(0, 2 * rows, n_a) / 2.0
    d_a = rng.integers(0, 256, (n_a, width), dtype=np.uint8)
    src = rng.integers(0, max(n_a, 1), n_b)
    v_b = rng.integers(0, 2 * rows, n_b) / 2.0
    d_b = rng.integers(0, 256, (n_b, width), dtype=np.uint8)
    if n_a:
        copy = rng.random(n_b) < 0.7
        v_b[copy] = v_a[src[copy]] + rng.integers(-14, 15, int(copy.sum())) / 2.0
        flips = (
            rng.integers(0, 256, (n_b, width), dtype=np.uint8)
            & (rng.random((n_b, width)) < 0.15).astype(np.uint8) * 255
        )
        d_b[copy] = d_a[src[copy]] ^ flips[copy]
    return v_a, d_a, v_b, d_b


@given(
    st.integers(0, 2**32 - 1),
    st.integers(0, 150),
    st.integers(0, 150),
    st.sampled_from([1, 2, 4, 32]),
    st.sampled_from([5, 40, 480]),
)
@settings(max_examples=200, deadline=None)
def test_the_guided_match_is_the_brute_force_match_in_the_band(
    seed: int, n_a: int, n_b: int, width: int, rows: int
) -> None:
    v_a, d_a, v_b, d_b = _random_features(seed, n_a, n_b, width, rows)
    got = cp.guided_matches(v_a, d_a, v_b, d_b, 6.0)
    want = _brute(v_a, d_a, v_b, d_b, 6.0)
    assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
    # the same pairs from the features in any order
    rng = np.random.default_rng(seed + 1)
    pa, pb = rng.permutation(n_a), rng.permutation(n_b)
    qi, tj = cp.guided_matches(v_a[pa], d_a[pa], v_b[pb], d_b[pb], 6.0)
    assert sorted(zip(pa[qi].tolist(), pb[tj].tolist())) == list(zip(*(w.tolist() for w in want)))


def test_the_guided_match_on_a_real_picture_pair(pano: np.ndarray) -> None:
    vc = VisualCompass(CAM)
    (uv_a, d_a), (uv_b, d_b) = (
        vc._features(view_of_panorama(pano, yaw, CAM.fx, CAM.fy)) for yaw in (0.3, 0.5)
    )
    assert d_a is not None and d_b is not None
    got = cp.guided_matches(uv_a[:, 1], d_a, uv_b[:, 1], d_b, vc.max_dv)
    want = _brute(uv_a[:, 1], d_a, uv_b[:, 1], d_b, vc.max_dv)
    assert len(got[0]) > 100
    assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])


def test_a_tie_between_the_two_nearest_is_no_match_and_a_single_nearest_is_kept() -> None:
    """Ties cannot pick a match: two equally near candidates fail the ratio test, and a
    unique nearest is the match whichever index it has; one candidate has no second to
    test against, and a feature outside every band has none."""
    d = np.array([[0b0000_0000], [0b0000_0000], [0b1111_1111], [0b0000_0001]], dtype=np.uint8)
    q = np.zeros((1, 1), dtype=np.uint8)
    tie = cp.guided_matches(np.zeros(1), q, np.zeros(3), d[[0, 1, 2]], 6.0)
    assert tie[0].size == 0
    for order in ([0, 2, 3], [3, 2, 0], [2, 0, 3]):
        qi, tj = cp.guided_matches(np.zeros(1), q, np.zeros(3), d[order], 6.0)
        assert qi.tolist() == [0] and tj.tolist() == [order.index(0)]
    lone = cp.guided_matches(np.zeros(1), q, np.array([0.0, 7.0]), d[[0, 2]], 6.0)
    assert lone[0].size == 0
    # the band is |v_b - v_a| <= max_dv, both ends in
    qi, tj = cp.guided_matches(np.zeros(1), q, np.array([-6.0, 6.0, 6.5]), d[[0, 2, 0]], 6.0)
    assert qi.tolist() == [0] and tj.tolist() == [0]


def test_keypoints_in_any_order_give_the_same_answer(pano: np.ndarray) -> None:
    vc = VisualCompass(CAM)
    fa = vc._features(view_of_panorama(pano, 0.3, CAM.fx, CAM.fy))
    fb = vc._features(view_of_panorama(pano, 0.3 + math.radians(12), CAM.fx, CAM.fy))
    want = vc.compare(fa, fb)
    assert want.ok
    rng = np.random.default_rng(3)
    for _ in range(5):
        pa, pb = rng.permutation(len(fa[0])), rng.permutation(len(fb[0]))
        assert fa[1] is not None and fb[1] is not None
        assert vc.compare((fa[0][pa], fa[1][pa]), (fb[0][pb], fb[1][pb])) == want


def test_the_guided_match_rejects_bad_inputs() -> None:
    d = np.zeros((3, 4), dtype=np.uint8)
    v = np.zeros(3)
    with pytest.raises(ValueError, match="2-D uint8"):
        cp.guided_matches(v, d.astype(np.int16), v, d, 6.0)
    with pytest.raises(ValueError, match="2-D uint8"):
        cp.guided_matches(v, d[0], v, d, 6.0)
    with pytest.raises(ValueError, match="widths differ"):
        cp.guided_matches(v, d, v, d[:, :2], 6.0)
    with pytest.raises(ValueError, match="one row per descriptor"):
        cp.guided_matches(v[:2], d, v, d, 6.0)
    for bad in (0.0, -1.0, math.inf, math.nan):
        with pytest.raises(ValueError, match="max_dv"):
            cp.guided_matches(v, d, v, d, bad)
    with pytest.raises(ValueError, match="finite"):
        cp.guided_matches(np.array([0.0, math.nan, 1.0]), d, v, d, 6.0)


def test_a_pictures_features_are_kept_and_give_the_same_answer(pano: np.ndarray) -> None:
    a = view_of_panorama(pano, 0.3, CAM.fx, CAM.fy)
    b = view_of_panorama(pano, 0.35, CAM.fx, CAM.fy)
    c = view_of_panorama(pano, 0.4, CAM.fx, CAM.fy)
    kept = VisualCompass(CAM)
    first = [kept.measure(a, b), kept.measure(b, c), kept.measure(a, c)]
    again = [kept.measure(a, b), kept.measure(b, c), kept.measure(a, c)]
    fresh = [VisualCompass(CAM).measure(x, y) for x, y in ((a, b), (b, c), (a, c))]
    assert first == again == fresh and all(r.ok for r in first)
    assert len(kept._cache) <= cp.FEATURE_CACHE
    # a picture changed in place is a new picture, never its old features
    d = a.copy()
    kept.measure(d, b)
    d[200:280, 300:340] = 255 - d[200:280, 300:340]
    assert kept.measure(d, b) == VisualCompass(CAM).measure(d, b)
