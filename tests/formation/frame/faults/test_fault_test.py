"""The per-robot fault test of the common frame (agent/core/formation/frame/faults/fault_test.py) and
the sighting noise model it rests on (agent/core/perception/sighting_noise.py)."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import binom, chi2

from agent.core.formation.frame.faults import fault_test as ft
from agent.core.formation.frame.faults import heading_test as ht
from agent.core.formation.frame.poses import PoseFrame, build_poses
from agent.core.perception.sighting_noise import P_MIN, SightingNoise, view_bin
from tests.formation.pose_fleets import fault, sim_layout, unaligned_records

#: A model matching the synthetic records below (±2 % distance, ±1° bearing, uniform).
NOISE = SightingNoise(
    r0=0.01, r1=0.015, t0=0.01, t1=0.012, g0=0.02, g1=0.0,
    sigma_mask=math.radians(4.0), w0=0.9, w90=0.05,
)  # fmt: skip


def fleet(seed: int, n: int = 8, kind: str = "", victim: int = 3) -> list:
    rng = np.random.default_rng(seed)
    pos = sim_layout(rng, n)
    heads = rng.uniform(-math.pi, math.pi, n)
    recs = unaligned_records(list(range(1, n + 1)), pos, heads, rng, 0.02, math.radians(1.0))
    if kind:
        recs = [fault(r, kind) if r.robot_id == victim else r for r in recs]
    return recs


# ------------------------------------------------------------------ the noise model
def test_chi2_splits_along_and_across_the_line_of_sight() -> None:
    m = SightingNoise(
        r0=0.1, r1=0.0, t0=0.05, t1=0.0, g0=0.0, g1=0.0, sigma_mask=0.1, w0=1.0, w90=0.0
    )
    v = np.array([[2.0, 0.0], [0.0, 1.0]])
    e = np.array([[0.1, 0.05], [0.05, 0.0]])  # 1σ along + 1σ across; 1σ across only
    assert m.chi2(v, e) == pytest.approx([2.0, 1.0])


def test_mask_density_is_a_density_over_half_a_turn() -> None:
    x = np.linspace(-math.pi / 2, math.pi / 2, 20001)
    f = NOISE.mask_density(x)
    assert float(np.trapezoid(f, x)) == pytest.approx(1.0, abs=1e-3)
    assert NOISE.mask_density(0.3) == pytest.approx(NOISE.mask_density(0.3 + math.pi))


def test_rejection_rate_is_clipped() -> None:
    m = SightingNoise(
        r0=0.1, r1=0.0, t0=0.1, t1=0.0, g0=-1.0, g1=10.0, sigma_mask=0.1, w0=1.0, w90=0.0
    )
    assert m.p_reject(0.0) == pytest.approx(1e-3) and m.p_reject(3.0) == pytest.approx(0.5)


@pytest.mark.parametrize(
    ("field", "value"),
    [("r0", 0.0), ("t0", -1.0), ("r1", -0.1), ("sigma_mask", 0.0), ("sigma_mask", 1.0),
     ("w0", 1.2), ("w90", -0.1), ("g0", math.nan), ("rho_untimed", 1.5), ("mask_scale", 0.0),
     ("bias_scale", math.inf), ("w180", -0.1), ("w180", 1.5), ("w180", math.nan),
     ("w180_view", (0.1,) * 5), ("w180_view", (0.1,) * 7), ("w180_view", (0.1,) * 5 + (1.2,)),
     ("w180_view", (math.nan,) * 6)],
)  # fmt: skip
def test_model_refuses_each_bad_field(field: str, value: float) -> None:
    good = dict(r0=0.1, r1=0.0, t0=0.1, t1=0.0, g0=0.0, g1=0.0, sigma_mask=0.1, w0=0.5, w90=0.2)
    with pytest.raises(ValueError):
        SightingNoise(**{**good, field: value})


def test_a_masks_reversal_rate_is_that_of_its_reading() -> None:
    """Bins of 30° of |θ| as read (0–30°, …, 150–180°, π itself in the last); no reading
    or no bins: the overall rate; clipped so that no mask is ever certain."""
    rates = (0.05, 0.1, 0.2, 0.3, 0.4, 0.6)
    m = replace(NOISE, w180=0.22, w180_view=rates)
    cases = [(0.0, 0), (math.radians(29.9), 0), (math.radians(-30.1), 1), (math.radians(95), 3),
             (math.radians(-170), 5), (math.pi, 5), (-math.pi, 5), (2 * math.pi + 0.1, 0)]  # fmt: skip
    for view, k in cases:
        assert view_bin(view) == k
        assert m.reversal(view) == rates[k]
    assert view_bin(math.nan) is None and m.reversal(math.nan) == 0.22
    assert replace(m, w180_view=()).reversal(math.pi) == 0.22
    edges = replace(m, w180_view=(0.0, 1.0, 0.5, 0.5, 0.5, 0.5))
    assert edges.reversal(0.0) == P_MIN and edges.reversal(math.radians(45)) == 1.0 - P_MIN


def test_model_round_trip_and_format(tmp_path: Path) -> None:
    NOISE.save(tmp_path)
    assert SightingNoise.load(tmp_path) == NOISE
    viewed = replace(NOISE, w180_view=(0.05, 0.1, 0.2, 0.3, 0.4, 0.6))
    viewed.save(tmp_path)
    assert SightingNoise.load(tmp_path) == viewed  # the JSON list comes back a tuple
    (tmp_path / "sighting_noise.json").write_text('{"format": 99}')
    with pytest.raises(ValueError, match="format"):
        SightingNoise.load(tmp_path)


def test_the_shipped_model_loads() -> None:
    m = SightingNoise.load()
    assert m.sightings > 1000 and 0.0 < m.sigma_radial(1.0) < 0.2


# ------------------------------------------------------------------ the statistics
def test_tail_known_answers() -> None:
    assert ft.tail_at_least([0.5, 0.5], 0) == 1.0
    assert ft.tail_at_least([0.5, 0.5], 1) == pytest.approx(0.75)
    assert ft.tail_at_least([0.5, 0.5], 2) == pytest.approx(0.25)
    assert ft.tail_at_least([0.1, 0.2], 2) == pytest.approx(0.02)
    assert ft.tail_at_least([], 1) == 0.0


@settings(max_examples=60, deadline=None)
@given(n=st.integers(1, 30), p=st.floats(0.001, 0.5), k=st.integers(0, 31))
def test_tail_is_the_binomial_for_equal_rates(n: int, p: float, k: int) -> None:
    assert ft.tail_at_least([p] * n, k) == pytest.approx(float(binom.sf(k - 1, n, p)), abs=1e-12)


def test_mask_test_finds_a_common_offset() -> None:
    assert ht.mask_test([], NOISE) == (0.0, 1.0)
    off, p = ht.mask_test([math.radians(a) for a in (39, 41, 40, 42)], NOISE)
    assert math.degrees(off) == pytest.approx(40.0, abs=2.0) and p < 1e-6
    off, p = ht.mask_test([math.radians(a) for a in (1, -2, 3, 88)], NOISE)
    assert p > 0.05  # one side/front confusion among correct masks: nothing


# ------------------------------------------------------------------ the verdict
def test_a_sound_fleet_passes() -> None:
    for seed in range(3):
        v = ft.fault_test(build_poses(fleet(seed)), NOISE)
        assert v.ok and v.named == () and v.poses is not None, v.reason


@pytest.mark.parametrize("kind", ["rotate", "scale", "shift"])
def test_the_faulty_robot_is_named(kind: str) -> None:
    v = ft.fault_test(build_poses(fleet(1, kind=kind, victim=3)), NOISE)
    assert v.ok and v.named == (3,), v.reason
    assert v.poses is not None and 3 not in v.poses.ids


def test_the_mask_scale_divides_wilks_statistic() -> None:
    deltas = [math.radians(a) for a in (9, 11, 10, 12)]
    _, p1 = ht.mask_test(deltas, NOISE)
    _, p2 = ht.mask_test(deltas, replace(NOISE, mask_scale=2.0))
    stat = float(chi2.isf(p1, 1))
    assert p2 == pytest.approx(float(chi2.sf(stat / 2.0, 1)), rel=1e-6) and p2 > p1


def test_masks_name_a_broken_compass_only_when_the_records_say_when() -> None:
    """A sound robot is seen turned as a whole at ``rho_untimed`` when records carry no
    times (masks as recorded), at ``rho`` when they do (masks turned back): a broken
    compass is named only from timed records when ``rho_untimed`` is above α."""
    model = replace(NOISE, rho=0.0, rho_untimed=0.08)
    recs = fleet(1, kind="rotate", victim=3)
    untimed = ft.fault_test(build_poses(recs), model, recs)
    assert untimed.named == (), untimed.reason
    still = np.array([[0.0, 1.0, 0.0]])  # every robot stood still all along
    timed = [replace(r, stances=still) for r in recs]
    v = ft.fault_test(build_poses(timed), model, timed)
    assert v.ok and v.named == (3,), v.reason


def test_same_verdict_for_shuffled_records() -> None:
    recs = fleet(2, kind="scale", victim=5)
    a = ft.fault_test(build_poses(recs), NOISE)
    order = np.random.default_rng(7).permutation(len(recs))
    b = ft.fault_test(build_poses([recs[k] for k in order]), NOISE)
    assert a.named == b.named == (5,) and a.reason == b.reason
    assert a.poses is not None and b.poses is not None
    assert np.array_equal(a.poses.positions, b.poses.positions)


def test_alpha_out_of_range_is_refused() -> None:
    poses = build_poses(fleet(0))
    for alpha in (0.0, 1.0, -0.1):
        with pytest.raises(ValueError, match="alpha"):
            ft.fault_test(poses, NOISE, alpha=alpha)


def test_a_wrong_pairing_is_a_rejected_pair_not_a_faulty_robot() -> None:
    recs = fleet(3)
    bad = recs[0]
    nb = bad.neighbours.copy()
    nb[0] = nb[0] * 1.6  # one sighting far off: that pair is rejected, robot 1 is sound
    recs[0] = type(bad)(bad.robot_id, nb, bad.orientations, bad.confidences)
    v = ft.fault_test(build_poses(recs), NOISE)
    assert v.ok and v.named == (), v.reason


def test_the_robot_left_out_stands_where_the_others_agree_it_is() -> None:
    # robot 3 is left out; one of the others' sightings of it is paired wrongly (a
    # sighting of some other place): the place is the consensus of the others, not a mean
    # dragged off by the one wrong sighting (which would make every sighting of the
    # consensus land nowhere)
    poses = build_poses(fleet(4))
    rest = ft._without(poses, 3)
    assert rest is not None
    seen = [m for m in poses.measurements if m.target == 3 and m.owner in rest.ids]
    assert len(seen) >= 3
    good = ft.seen_by_others(poses, rest, 3, NOISE)
    wrong = replace(seen[0], vector=np.asarray(seen[0].vector) * -1.0)
    others = [m for m in poses.measurements if m is not seen[0]]
    bad = replace(poses, measurements=(wrong, *others))
    at = ft.seen_by_others(bad, rest, 3, NOISE)
    mean = np.mean([rest.to_common(m.owner, m.vector)[0] for m in [wrong, *seen[1:]]], axis=0)
    assert float(np.hypot(*(at - good))) < 0.05
    assert float(np.hypot(*(mean - good))) > 0.2


def test_two_faulty_robots_that_never_saw_each_other_stop_the_fleet() -> None:
    # leaving one out cannot explain the other (they share no sighting): nobody is
    # named, and nobody moves
    recs = fleet(1, n=12)
    poses = build_poses(recs)
    assert not any({m.owner, m.target} == {1, 5} for m in poses.measurements)
    bad = [fault(r, "scale") if r.robot_id in (1, 5) else r for r in recs]
    v = ft.fault_test(build_poses(bad), NOISE, bad)
    assert not v.ok and v.named == () and "beyond one robot" in v.reason, v.reason


def _cut(poses: PoseFrame, robot: int, keep: int) -> PoseFrame:
    """``poses`` with only the first ``keep`` of ``robot``'s own measurements."""
    own = [m for m in poses.measurements if m.owner == robot]
    rest = [m for m in poses.measurements if m.owner != robot]
    return replace(poses, measurements=tuple(rest + own[:keep]))


def test_unpaired_are_the_sightings_no_pair_uses() -> None:
    recs = fleet(1)
    poses = build_poses(recs)
    cut = _cut(poses, 3, 1)
    loose = ft.unpaired(cut, recs)
    assert set(loose) == {3}
    used = {tuple(m.vector) for m in cut.measurements if m.owner == 3}
    mine = [tuple(v) for v in recs[2].neighbours if tuple(v) not in used]
    assert [tuple(v) for v in loose[3]] == mine and len(mine) >= 2


def test_a_scaled_robot_whose_sightings_did_not_pair_is_named_from_any_order() -> None:
    """Robot 3's distances 40 % too long, and only one of its sightings paired: the bias
    test takes the unpaired ones from its record, each landing on the robot it saw under
    the fitted bias; the verdict is the same for the records in any order."""
    recs = fleet(2, kind="scale", victim=3)
    poses = _cut(build_poses(recs), 3, 1)
    v = ft.fault_test(poses, NOISE, recs)
    assert v.ok and v.named == (3,), v.reason
    order = np.random.default_rng(3).permutation(len(recs))
    w = ft.fault_test(poses, NOISE, [recs[k] for k in order])
    assert w.named == v.named and w.reason == v.reason
    (t3,) = [t for t in v.tests if t.robot == 3]
    assert t3.p_bias < 1e-6, t3.describe()


@pytest.mark.parametrize("kind", ["", "scale", "rotate"])
def test_whether_anyone_is_rejected_is_the_full_tests_answer(kind: str) -> None:
    # the search asks only whether the rest rejects anyone: the bias test is skipped once
    # a cheap test has, never changing the answer
    recs = fleet(5, kind=kind)
    poses = build_poses(recs)
    ev = ft._evidence(poses, NOISE, recs, None)
    full = ft._robot_tests(poses, NOISE, ev)
    for alpha in (ft.ALPHA, 0.5, min(t.p for t in full) * 1.5):
        want = any(t.p < alpha for t in full)
        assert ft._rejects_anyone(poses, NOISE, ev, alpha) == want


def test_one_fault_explains_known_answers() -> None:
    """At ALPHA = 1e-4: one or two robots rejected (the faulty one and at most one false
    alarm) fit the single-fault model; three do not until C(n−1, 2)·ALPHA² reaches ALPHA
    (n ≈ 143); a frame rejecting every robot never does."""
    assert ft.ALPHA == 1e-4
    for n in (3, 10, 40, 100):
        assert ft.one_fault_explains(0, n) and ft.one_fault_explains(1, n)
        assert ft.one_fault_explains(2, n)
        assert not ft.one_fault_explains(3, n) and not ft.one_fault_explains(n, n)
    assert ft.one_fault_explains(3, 200)
    for k, n in ((2, 10), (3, 100), (3, 200), (4, 400)):  # the binomial tail by scipy.stats
        want = binom.sf(k - 2, n - 1, ft.ALPHA) >= ft.ALPHA
        assert ft.one_fault_explains(k, n) == want


@pytest.mark.parametrize(("k", "n"), [(-1, 3), (4, 3), (0, -1)])
def test_one_fault_explains_refuses_impossible_counts(k: int, n: int) -> None:
    with pytest.raises(ValueError, match="rejected <= robots"):
        ft.one_fault_explains(k, n)
