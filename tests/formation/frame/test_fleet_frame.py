"""The fleet's frame for planning (agent/core/formation/frame/fleet_frame.py, docs/design.md §9)."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest

from agent.core.formation.frame.fleet_frame import fleet_frame
from agent.core.formation.frame.neighbour_check import DEFAULT_EPSILON
from agent.core.formation.frame.pose_check import check_poses
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
    are identified where they land) never run the pose pairing; a turned robot does."""
    import agent.core.formation.frame.fleet_frame as ff_mod

    calls: list[int] = []
    real = ff_mod.build_poses

    def counted(*args: Any) -> Any:
        calls.append(1)
        return real(*args)

    monkeypatch.setattr(ff_mod, "build_poses", counted)
    rng = np.random.default_rng(4)
    pos = sim_layout(rng, 12)
    heads = np.full(12, math.pi / 2)
    recs = unaligned_records(list(range(1, 13)), pos, heads, rng, 0.03, math.radians(2))
    ff = fleet_frame(recs, DEFAULT_EPSILON)
    assert ff.aligned and calls == []
    heads[5] += math.radians(70)  # robot 6 set down turned
    recs = unaligned_records(list(range(1, 13)), pos, heads, rng, 0.03, math.radians(2))
    ff = fleet_frame(recs, DEFAULT_EPSILON)
    assert calls == [1]
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


def _inject(monkeypatch: pytest.MonkeyPatch, ff_mod: Any, verdict: Any) -> None:
    """fleet_frame fits ``verdict.poses`` and its check says ``verdict``."""
    monkeypatch.setattr(ff_mod, "build_poses", lambda r, e: verdict.poses)
    monkeypatch.setattr(ff_mod, "quick_check", lambda poses: None)
    monkeypatch.setattr(ff_mod, "check_frame", lambda poses: verdict)


def test_a_fleet_that_falls_apart_without_the_named_robot_stops(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import dataclasses

    import agent.core.formation.frame.fleet_frame as ff_mod
    from agent.core.formation.frame.pose_check import PoseVerdict

    _, _, recs = _fleet(4)
    real = check_poses(recs, DEFAULT_EPSILON)
    worse = tuple(
        dataclasses.replace(q, score=5.0, position=1.0) if 2 in (q.i, q.j) else q
        for q in real.poses.pairs
    )
    poses = dataclasses.replace(real.poses, pairs=worse)
    named = PoseVerdict((2,), "robot 2: the others are consistent without it", poses)
    _inject(monkeypatch, ff_mod, named)
    monkeypatch.setattr(ff_mod, "consistent_rest", lambda poses, robot: None)
    with pytest.raises(ValueError, match=r"robot 2's sightings do not fit.*nobody moves"):
        fleet_frame(recs, DEFAULT_EPSILON)


def test_a_large_fleet_inconsistent_beyond_one_robot_stops(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Beyond UNEXPLAINED_MAX_N robots an unexplained misfit stops the fleet: its own
    check after hold cannot tell a wrong dense pyramid (50 NAOs, seed 13)."""
    import dataclasses

    import agent.core.formation.frame.fleet_frame as ff_mod
    from agent.core.formation.frame.pose_check import PoseVerdict

    for n, stops in ((ff_mod.UNEXPLAINED_MAX_N, False), (ff_mod.UNEXPLAINED_MAX_N + 1, True)):
        rng = np.random.default_rng(n)
        ids = list(range(1, n + 1))
        recs = unaligned_records(ids, sim_layout(rng, n), rng.uniform(-math.pi, math.pi, n))
        real = check_poses(recs, DEFAULT_EPSILON)
        worse = tuple(dataclasses.replace(p, score=5.0) for p in real.poses.pairs)
        _inject(
            monkeypatch,
            ff_mod,
            PoseVerdict((), "ambiguous", dataclasses.replace(real.poses, pairs=worse)),
        )
        if stops:
            with pytest.raises(ValueError, match=rf"ambiguous.*a fleet of {n} .*nobody moves"):
                fleet_frame(recs, DEFAULT_EPSILON)
        else:
            assert fleet_frame(recs, DEFAULT_EPSILON).reason == "ambiguous"


def test_a_fleet_inconsistent_beyond_one_robot_plans_as_the_papers_do(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import dataclasses

    import agent.core.formation.frame.fleet_frame as ff_mod
    from agent.core.formation.frame.pose_check import PoseVerdict

    _, _, recs = _fleet(4)
    real = check_poses(recs, DEFAULT_EPSILON)
    worse = [dataclasses.replace(p, score=5.0) for p in real.poses.pairs]
    poses = dataclasses.replace(real.poses, pairs=tuple(worse))
    _inject(monkeypatch, ff_mod, PoseVerdict((), "ambiguous", poses))
    got = fleet_frame(recs, DEFAULT_EPSILON)  # random headings: eq. 9 pairs nobody
    assert got.reason == "ambiguous" and not got.aligned
    _, _, aligned = _fleet(3, np.full(len(IDS), math.pi / 2))
    real = check_poses(aligned, DEFAULT_EPSILON)
    bad = dataclasses.replace(
        real.poses, pairs=tuple(dataclasses.replace(p, score=5.0) for p in real.poses.pairs)
    )
    _inject(monkeypatch, ff_mod, PoseVerdict((), "noisy", bad))
    got = fleet_frame(aligned, DEFAULT_EPSILON)  # the papers' model explains every position
    assert got.aligned and got.reason == "aligned starts: every sighting fits in position"


def test_one_misfit_pair_names_nobody(monkeypatch: pytest.MonkeyPatch) -> None:
    """A single misfit pair blames neither end unless the other end was tested and cleared
    (agent/core/formation/frame/pose_check.py, check_frame)."""
    import agent.core.formation.frame.pose_check as pc

    _, _, recs = _fleet(4)
    real = pc.check_poses(recs, DEFAULT_EPSILON).poses
    first = real.pairs[0]
    one_bad = tuple(
        dataclasses.replace(q, position=5.0, score=3.0) if q is first else q for q in real.pairs
    )
    poses = dataclasses.replace(real, pairs=one_bad)
    named = pc.PoseVerdict((first.i,), f"robot {first.i}: one bad pair", poses)
    monkeypatch.setattr(pc, "_check_frame", lambda p: named)
    got = pc.check_frame(poses)  # the other end, left out, leaves a consistent rest
    assert got.named == () and got.reason.startswith("nobody named, < 2 pairs")
    two_bad = tuple(
        dataclasses.replace(q, position=5.0, score=3.0) if first.i in (q.i, q.j) else q
        for q in real.pairs
    )
    poses = dataclasses.replace(real, pairs=two_bad)
    named = pc.PoseVerdict((first.i,), f"robot {first.i}: two bad pairs", poses)
    monkeypatch.setattr(pc, "_check_frame", lambda p: named)
    assert len(pc.bad_pairs(poses, first.i)) >= 2
    assert pc.check_frame(poses).named == (first.i,)


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


def test_a_turned_robot_is_named_by_the_others_masks() -> None:
    """A broken compass (record turned 40°) fits in position, ψ absorbs it; the others'
    masks of it agree on the offset, and the fleet leaves it out."""
    rng = np.random.default_rng(7)
    ids = list(range(1, 7))
    pos = sim_layout(rng, 6)
    recs = unaligned_records(ids, pos, rng.uniform(-math.pi, math.pi, 6), rng, 0.03, 0.03)
    recs[3] = fault(recs[3], "rotate")
    ff = fleet_frame(recs, DEFAULT_EPSILON)
    assert ff.excluded == (4,) and "masks agree" in ff.reason


def test_an_aligned_fleet_with_misfit_pairs_plans_without_the_search(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The search for a robot to blame (one fit per robot) is not run when the
    frame is the papers' aligned one anyway; the same frame as with the search."""
    import dataclasses

    import agent.core.formation.frame.fleet_frame as ff_mod

    _, _, aligned = _fleet(3, np.full(len(IDS), math.pi / 2))
    real = check_poses(aligned, DEFAULT_EPSILON).poses
    # two misfit pairs sharing robot 2: no isolated wrong pairing, nobody turned
    worse = tuple(
        dataclasses.replace(p, score=5.0, position=1.0) if 2 in (p.i, p.j) else p
        for p in real.pairs
    )
    misfit = dataclasses.replace(real, pairs=worse)
    assert not misfit.consistent and not misfit.turned
    monkeypatch.setattr(ff_mod, "build_poses", lambda r, e: misfit)
    monkeypatch.setattr(ff_mod, "_aligned_explains", lambda a, p: None)
    monkeypatch.setattr(ff_mod, "_aligned_at_once", lambda a, g, r: None)  # the slow path
    with_search = fleet_frame(aligned, DEFAULT_EPSILON)

    def no_search(poses: Any) -> Any:
        raise AssertionError("the search ran")

    monkeypatch.setattr(ff_mod, "check_frame", no_search)
    got = fleet_frame(aligned, DEFAULT_EPSILON)
    assert got.aligned and got.excluded == ()
    assert got.reason == "aligned starts (every |ψ| ≤ 10°): pairs misfit, nobody sought to blame"
    assert got.positions.tobytes() == with_search.positions.tobytes()


def test_quick_check_answers_only_without_the_search() -> None:
    import dataclasses

    from agent.core.formation.frame.pose_check import check_frame, quick_check

    _, _, recs = _fleet(4)
    poses = check_poses(recs, DEFAULT_EPSILON).poses
    ok = quick_check(poses)
    assert ok is not None and ok.named == () and ok.reason.startswith("consistent")
    assert ok == check_frame(poses)
    turned = dataclasses.replace(
        poses, pairs=tuple(dataclasses.replace(p, score=5.0) for p in poses.pairs), turned=(2,)
    )
    assert quick_check(turned) is None  # a turned robot: only the search can tell


def _with_pairs(scores: dict[tuple[int, int], float], turned: tuple[int, ...] = ()) -> Any:
    import dataclasses

    from agent.core.formation.frame.poses import PairResidual

    _, _, recs = _fleet(4)
    poses = check_poses(recs, DEFAULT_EPSILON).poses
    pairs = tuple(PairResidual(i, j, s, 0.0, 1.0, s) for (i, j), s in sorted(scores.items()))
    return dataclasses.replace(poses, pairs=pairs, turned=turned)


def test_may_explain_known_answers() -> None:
    from agent.core.formation.frame.pose_check import may_explain

    # robot 2 is an end of every misfit pair: the only one whose leaving can clear them
    one = _with_pairs({(1, 2): 3.0, (2, 3): 2.0, (2, 4): 4.0, (3, 4): 0.5})
    # cleaning: left out, 3 leaves 1-2 and 2-4, which share robot 2: not isolated
    assert may_explain(one, False) == [2] and may_explain(one, True) == [2]
    two = _with_pairs({(1, 2): 3.0, (3, 4): 2.0, (4, 5): 0.2})
    assert may_explain(two, False) == []  # two disjoint misfit pairs: nobody alone
    assert may_explain(two, True) == [1, 2, 3, 4]  # the other one is isolated
    spread = _with_pairs({(1, 2): 3.0, (2, 3): 2.0, (4, 5): 2.0, (5, 6): 9.0})
    assert may_explain(spread, True) == []  # the misfit spreads: the search is not run
    turned = _with_pairs({(1, 2): 0.5}, turned=(5,))
    assert may_explain(turned, False) == [5]  # no misfit pair, a turned robot
    assert may_explain(_with_pairs({(1, 2): 0.5}), False) == []
