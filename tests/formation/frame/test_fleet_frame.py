"""The fleet's frame for planning (agent/core/formation/frame/fleet_frame.py, docs/design.md §9)."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest

from agent.core.formation.frame.faults.fault_test import FaultVerdict, FleetCount, RobotTest
from agent.core.formation.frame.fleet_frame import DOUBT, fleet_frame, surprise
from agent.core.formation.frame.neighbour_check import DEFAULT_EPSILON
from agent.core.perception.sighting_noise import SightingNoise
from tests.formation.pose_fleets import fault, sim_layout, unaligned_records

IDS = [1, 2, 3, 4, 5, 6]


def _fleet(seed: int, headings: np.ndarray | None = None):  # type: ignore[no-untyped-def]
    rng = np.random.default_rng(seed)
    pos = sim_layout(rng, len(IDS))
    h = rng.uniform(-math.pi, math.pi, len(IDS)) if headings is None else headings
    return pos, h, unaligned_records(IDS, pos, h)


def test_aligned_starts_are_planned_without_the_pose_pairing(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Aligned starts the papers' model explains (or explains once its sightings
    are identified where they land) never run the pose pairing; a turned robot is found
    turned (by the heading vote of the refined aligned model, or by the pose fit)."""
    import agent.core.formation.frame.fleet_frame as ff_mod

    calls: list[int] = []
    real = ff_mod.fit_from_graph

    def counted(*args: Any) -> Any:
        calls.append(1)
        return real(*args)

    monkeypatch.setattr(ff_mod, "fit_from_graph", counted)
    rng = np.random.default_rng(4)
    pos = sim_layout(rng, 12)
    heads = np.full(12, math.pi / 2)
    recs = unaligned_records(list(range(1, 13)), pos, heads, rng, 0.03, math.radians(2))
    noise = SightingNoise.synthetic(0.01, 0.03, math.radians(2))  # these records' noise
    ff = fleet_frame(recs, DEFAULT_EPSILON, noise)
    assert ff.aligned and calls == []
    heads[5] += math.radians(70)  # robot 6 set down turned
    recs = unaligned_records(list(range(1, 13)), pos, heads, rng, 0.03, math.radians(2))
    ff = fleet_frame(recs, DEFAULT_EPSILON, noise)
    assert not ff.aligned and ff.excluded == ()
    assert abs(ff.heading_of(6) - math.radians(70)) < math.radians(5)


def test_aligned_starts_keep_the_papers_model() -> None:
    _, _, recs = _fleet(3, np.full(len(IDS), math.pi / 2))
    ff = fleet_frame(recs, DEFAULT_EPSILON)
    assert ff.aligned and ff.excluded == () and ff.ids == tuple(IDS)
    assert np.all(ff.headings == 0.0)


def test_random_headings_are_recovered_without_noise() -> None:
    pos, h, recs = _fleet(4)
    ff = fleet_frame(recs, DEFAULT_EPSILON)
    k = ff.ids.index(ff.frame_robot)
    psi_true = h - h[IDS.index(ff.frame_robot)]
    for rid in ff.ids:
        assert math.cos(ff.heading_of(rid) - psi_true[IDS.index(rid)]) == pytest.approx(1.0)
    # positions: the same shape as the world's (distances between robots)
    d_est = np.hypot(*(ff.positions[None] - ff.positions[:, None]).transpose(2, 0, 1))
    d_true = np.hypot(*(pos[None] - pos[:, None]).transpose(2, 0, 1))
    np.testing.assert_allclose(d_est, d_true, atol=1e-6)
    assert ff.positions[k] == pytest.approx([0.0, 0.0])


@pytest.mark.parametrize("kind", ["scale", "shift"])
def test_a_faulty_robot_is_left_out_and_placed_where_the_others_saw_it(kind: str) -> None:
    pos, h, recs = _fleet(1)
    bad = 3
    recs = [fault(r, kind) if r.robot_id == bad else r for r in recs]
    ff = fleet_frame(recs, DEFAULT_EPSILON)
    assert ff.excluded == (bad,) and bad not in ff.ids and f"robot {bad}" in ff.reason
    # its place, seen by the others, matches the world's (up to the rigid frame)
    k = IDS.index(ff.frame_robot)
    w = pos[IDS.index(bad)] - pos[k]
    psi_f = h[k] - math.pi / 2
    c, s = math.cos(-psi_f), math.sin(-psi_f)
    expected = np.array([c * w[0] - s * w[1], s * w[0] + c * w[1]])
    np.testing.assert_allclose(ff.excluded_at[0], expected, atol=1e-6)


def test_shuffled_records_give_the_same_frame() -> None:
    _, _, recs = _fleet(11)
    a = fleet_frame(recs, DEFAULT_EPSILON)
    b = fleet_frame(list(reversed(recs)), DEFAULT_EPSILON)
    assert a.ids == b.ids and a.frame_robot == b.frame_robot
    assert a.positions.tobytes() == b.positions.tobytes()
    assert a.headings.tobytes() == b.headings.tobytes()


def test_heading_of_a_robot_not_planned() -> None:
    _, _, recs = _fleet(4)
    with pytest.raises(ValueError, match="not planned"):
        fleet_frame(recs, DEFAULT_EPSILON).heading_of(99)


def test_aligned_starts_with_wrong_masks_leave_nobody_out() -> None:
    """Masks alone never overrule the papers' aligned model (a wrong mask match is common)."""
    _, _, recs = _fleet(3, np.full(len(IDS), math.pi / 2))
    bent = []
    for r in recs:
        ori = None if r.orientations is None else np.mod(r.orientations + 1.2, 2 * math.pi)
        bent.append(r if r.robot_id != 2 else dataclasses.replace(r, orientations=ori))
    ff = fleet_frame(bent, DEFAULT_EPSILON)
    assert ff.aligned and ff.excluded == () and np.all(ff.headings == 0.0)


def test_wrong_masks_never_send_a_turned_fleet_to_aligned_frames() -> None:
    """Ten robots within ±20° of north, a third of the masks wrong by ±60-90° (as in the
    simulator's 10-NAO runs): the fit's ψ are used, not the papers' aligned model, whose
    plans would be turned by every robot's real heading."""
    rng = np.random.default_rng(20)
    ids = list(range(1, 11))
    pos = sim_layout(rng, 10)
    h = math.pi / 2 + rng.uniform(-math.radians(20), math.radians(20), 10)
    recs = unaligned_records(ids, pos, h, rng, 0.02, math.radians(1))
    bent = []
    for r in recs:
        assert r.orientations is not None
        wrong = rng.random(r.count) < 0.33
        off = rng.choice([-1.0, 1.0], r.count) * rng.uniform(1.05, 1.57, r.count)
        bent.append(dataclasses.replace(r, orientations=r.orientations + np.where(wrong, off, 0)))
    ff = fleet_frame(bent, DEFAULT_EPSILON)
    assert not ff.aligned and ff.excluded == ()
    k = ids.index(ff.frame_robot)
    for rid in ids:
        err = ff.heading_of(rid) - (h[ids.index(rid)] - h[k])
        assert abs(math.remainder(err, 2 * math.pi)) < math.radians(3)


@pytest.mark.parametrize(("rho", "named"), [(0.0, (4,)), (0.07, ())])
def test_masks_name_a_turned_robot_only_when_better_than_rho(
    rho: float, named: tuple[int, ...]
) -> None:
    """A broken compass (record turned 40°) fits in position, ψ absorbs it; only the
    others' masks of it disagree, by one offset. With masks that err independently
    (ρ = 0) they name it; with the measured rate ρ of sound robots seen turned as a whole
    they cannot tell it from one, and nobody is named (docs/design.md §9). These records
    carry no times: the rate of that kind, ``rho_untimed``, is the one that counts."""
    rng = np.random.default_rng(7)
    ids = list(range(1, 7))
    pos = sim_layout(rng, 6)
    recs = unaligned_records(ids, pos, rng.uniform(-math.pi, math.pi, 6), rng, 0.03, 0.03)
    recs[3] = fault(recs[3], "rotate")
    noise = dataclasses.replace(SightingNoise.synthetic(0.01, 0.03, 0.03), rho_untimed=rho)
    ff = fleet_frame(recs, DEFAULT_EPSILON, noise)
    assert ff.excluded == named, ff.reason


def _verdict(global_p: float, robot_p: list[float]) -> FaultVerdict:
    tests = tuple(
        RobotTest(i + 1, 3, 0, 0, 0, 1.0, 2, 0.0, 1.0, 0.0, p / 3.0) for i, p in enumerate(robot_p)
    )
    return FaultVerdict(True, (), None, (), tests, "", FleetCount(0, 10, global_p))


def test_a_frame_surprises_by_its_global_test_or_its_worst_robot_over_the_fleet() -> None:
    """By hand: the smaller of the global p and the worst robot's p times n."""
    assert surprise(_verdict(0.5, [0.9, 0.3, 1.0])) == pytest.approx(0.5)
    assert surprise(_verdict(0.5, [0.9, 0.03, 1.0])) == pytest.approx(0.09)
    assert surprise(_verdict(0.004, [0.9, 0.03, 1.0])) == pytest.approx(0.004)
    # the shifted robot's frame of the recorded run: its worst robot 3.3e-4 of seven
    assert surprise(_verdict(0.3, [3.3e-4, *[0.5] * 6])) < DOUBT
    assert surprise(_verdict(0.3, [])) == pytest.approx(0.3)


def test_surprise_needs_the_global_test() -> None:
    v = _verdict(0.5, [0.9])
    with pytest.raises(ValueError, match="without its global test"):
        surprise(FaultVerdict(v.ok, v.named, v.poses, v.dropped, v.tests, v.reason, None))


def _rests_passing(monkeypatch: pytest.MonkeyPatch, passing: set[int]) -> list[tuple[int, ...]]:
    """Make the rest framed without a robot's record pass exactly when that robot is in
    ``passing`` (with the true poses of :func:`_fleet` (1), in the lowest robot's fixed
    frame); returns the robots tried, in order."""
    import agent.core.formation.frame.fleet_frame as ff_mod

    pos, h, _ = _fleet(1)
    tried: list[tuple[int, ...]] = []
    real = ff_mod._first_passed

    def fake(records, epsilon, model, suspects, unrecorded=False):  # type: ignore[no-untyped-def]
        if suspects is not None:
            return real(records, epsilon, model, suspects, unrecorded)
        assert unrecorded  # the rest is framed knowing one robot stands without a record
        ids = tuple(sorted(r.robot_id for r in records))
        left = tuple(sorted(set(IDS) - set(ids)))
        tried.append(left)
        if left[0] not in passing:
            return None, "a fake reason"
        rows = [IDS.index(i) for i in ids]
        psi_f = h[rows[0]] - math.pi / 2
        c, s = math.cos(-psi_f), math.sin(-psi_f)
        w = pos[rows] - pos[rows[0]]
        fixed = np.stack([c * w[:, 0] - s * w[:, 1], s * w[:, 0] + c * w[:, 1]], axis=1)
        frame = ff_mod.FleetFrame(ids[0], ids, fixed, h[rows] - h[rows[0]], False, reason="fake")
        return frame, "fake"

    monkeypatch.setattr(ff_mod, "_first_passed", fake)
    return tried


def _two_faulty() -> list[Any]:
    _, _, recs = _fleet(1)
    return [fault(r, "scale") if r.robot_id in (2, 5) else r for r in recs]


def test_framed_again_without_one_record_names_that_robot(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """No candidate passes (two robots faulty); the suspects are tried smallest p first,
    and the one whose rest, framed again without its record, passes is named."""
    recs = _two_faulty()
    with pytest.raises(ValueError):
        fleet_frame(recs, DEFAULT_EPSILON)  # no single robot explains it
    tried = _rests_passing(monkeypatch, {5})
    ff = fleet_frame(recs, DEFAULT_EPSILON)
    assert ff.excluded == (5,) and 5 not in ff.ids and "framed again" in ff.reason
    assert (5,) in tried and len(set(tried)) == len(tried)  # each suspect tried once
    # it stands where the others saw it: the world's place, in the rest's frame
    pos, h, _ = _fleet(1)
    psi_f = h[0] - math.pi / 2
    c, s = math.cos(-psi_f), math.sin(-psi_f)
    w = pos[IDS.index(5)] - pos[0]
    expected = np.array([c * w[0] - s * w[1], s * w[0] + c * w[1]])
    np.testing.assert_allclose(ff.excluded_at[0], expected, atol=1e-6)


def test_framed_again_two_robots_whose_rests_pass_is_ambiguous(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Two suspects whose rests both pass: nobody can be trusted, the fleet stops."""
    tried = _rests_passing(monkeypatch, {2, 5})
    with pytest.raises(ValueError, match="no frame passes"):
        fleet_frame(_two_faulty(), DEFAULT_EPSILON)
    assert len(tried) >= 2


def test_framed_again_no_rest_passes_stops(monkeypatch: pytest.MonkeyPatch) -> None:
    tried = _rests_passing(monkeypatch, set())
    with pytest.raises(ValueError, match="no frame passes"):
        fleet_frame(_two_faulty(), DEFAULT_EPSILON)
    assert tried  # the suspects were tried


def test_a_fault_free_fleet_never_reframes(monkeypatch: pytest.MonkeyPatch) -> None:
    tried = _rests_passing(monkeypatch, set(IDS))
    ff = fleet_frame(_fleet(1)[2], DEFAULT_EPSILON)
    assert ff.excluded == () and tried == []
