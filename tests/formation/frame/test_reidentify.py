"""Sightings identified where they land (agent/core/formation/frame/reidentify.py): known
answers for the gate, the vote and the identification, a dense fleet with a robot fitted
turned round, junk detections between robots, and determinism under shuffled records."""

from __future__ import annotations

import math
from functools import partial

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.formation.frame.fleet_frame import fleet_frame
from agent.core.formation.frame.pose_pairing import wrap_angle
from agent.core.formation.frame.poses import build_poses, evaluate_poses
from agent.core.formation.frame.records import NeighborRecord
from agent.core.formation.frame.reidentify import (
    AMBIGUITY,
    GATE,
    GATE_REL,
    MIN_APART,
    MIN_SIGHTINGS,
    RESEAT_GAIN,
    RESEAT_SHARE,
    _counted_where_needed,
    _landings,
    _place,
    _position_landings,
    _seen_on,
    gate,
    heading_bound,
    identify_sightings,
    landing,
    mostly_land,
    own_bound,
    refine_poses,
    reseat_headings,
    reseat_positions,
    seen_counts,
)
from tests.formation.pose_fleets import rot, sim_layout, unaligned_records

GRID = np.array([[x, y] for y in (0.0, 1.0, 2.0) for x in (0.0, 1.0, 2.0)])  # 3 × 3, 1 m


def _sightings(pos: np.ndarray, k: int, psi: float, scale: float = 1.0) -> np.ndarray:
    """Robot k's sightings of every other robot, in a fixed frame turned by ψ."""
    w = np.delete(pos, k, axis=0) - pos[k]
    return np.asarray(scale * w @ rot(psi))  # R(−ψ) w, row-wise


def test_gate_by_hand() -> None:
    assert (GATE, GATE_REL) == (0.12, 0.06)
    assert float(gate(2.0)) == pytest.approx(0.24)


def test_landing_known_answers() -> None:
    pos = np.array([[0.0, 0.0], [1.0, 0.0], [3.0, 0.0], [1.0, 2.0], [1.0, 2.3]])
    pts = np.array([[1.05, 0.0], [2.0, 0.0], [0.02, 0.0], [1.0, 2.14]])
    dist = np.array([1.0, 2.0, 0.02, 2.4])
    # on robot 1; between 1 and 2 (1 m from both): nobody; on the owner itself: never;
    # 0.14 m from robot 3 but 0.16 m from robot 4: ambiguous
    assert landing(pos, 0, pts, dist).tolist() == [1, -1, -1, -1]


def test_landing_with_too_few_robots_or_points() -> None:
    assert landing(np.zeros((1, 2)), 0, np.ones((2, 2)), np.ones(2)).tolist() == [-1, -1]
    assert landing(GRID, 0, np.zeros((0, 2)), np.zeros(0)).shape == (0,)


def test_a_robot_fitted_turned_round_is_reseated() -> None:
    sightings = [_sightings(GRID, k, 0.0) for k in range(9)]
    psi = np.zeros(9)
    psi[0] = math.pi  # the corner robot, fitted facing backwards: all 8 land on nobody
    out = reseat_headings(GRID, psi, sightings)
    assert abs(out[0]) < 1e-9
    assert np.array_equal(out[1:], np.zeros(8))  # the others are not voted on
    # (the centre robot could not be told: the grid looks the same turned round)
    psi[0], psi[4] = 0.0, math.pi
    assert reseat_headings(GRID, psi, sightings)[4] == math.pi


def test_a_robot_with_wrong_distances_keeps_its_heading() -> None:
    sightings = [_sightings(GRID, k, 0.0) for k in range(9)]
    sightings[4] = _sightings(GRID, 4, 0.0, scale=1.4)  # a D-base off by 40 %
    psi = np.zeros(9)
    psi[4] = 0.3
    assert reseat_headings(GRID, psi, sightings)[4] == 0.3


def test_too_few_sightings_are_not_voted_on() -> None:
    sightings = [_sightings(GRID, k, 0.0)[:2] for k in range(9)]
    psi = np.full(9, math.pi)
    assert np.array_equal(reseat_headings(GRID, psi, sightings), psi)


def test_a_robot_fitted_out_of_place_is_reseated_where_its_sightings_land() -> None:
    sightings = [_sightings(GRID, k, 0.0) for k in range(9)]
    pos = GRID.copy()
    pos[0] = [-0.9, 0.5]  # 1 m off: none of its 8 sightings lands
    out = reseat_positions(pos, np.zeros(9), sightings)
    assert np.array_equal(out[0], GRID[0])  # exactly: the candidate is a robot minus a sighting
    assert np.array_equal(out[1:], GRID[1:])
    assert np.array_equal(pos[0], [-0.9, 0.5])  # the input is not changed


def test_a_robot_with_wrong_distances_keeps_its_position() -> None:
    sightings = [_sightings(GRID, k, 0.0) for k in range(9)]
    sightings[4] = _sightings(GRID, 4, 0.0, scale=1.4)  # lands on nobody, where it stands
    out = reseat_positions(GRID, np.zeros(9), sightings)
    assert np.array_equal(out, GRID)


def test_the_others_sightings_keep_a_robot_where_they_see_it() -> None:
    # robot 8's own sightings are those of a robot at (2.5, 2.5): all 8 would land there,
    # but the other 8 robots see it at (2, 2), and nobody sees it at (2.5, 2.5)
    sightings = [_sightings(GRID, k, 0.0) for k in range(9)]
    sightings[8] = np.delete(GRID, 8, axis=0) - np.array([2.5, 2.5])
    assert np.array_equal(reseat_positions(GRID, np.zeros(9), sightings), GRID)
    # without the others' sightings of it the vote moves it: the guard is what holds it
    alone = [np.zeros((0, 2))] * 8 + [sightings[8]]
    assert np.allclose(reseat_positions(GRID, np.zeros(9), alone)[8], [2.5, 2.5])


def test_no_position_is_voted_next_to_another_robot() -> None:
    # robot 1's sightings would all land from 0.2 m beside robot 0: refused (MIN_APART)
    pos = np.array([[0.0, 0.0], [5.0, 5.0], [2.0, 0.0], [0.0, 2.0], [2.0, 2.0]])
    true_1 = np.array([0.2, 0.0])
    sightings = [np.zeros((0, 2)), pos[[0, 2, 3, 4]] - true_1] + [np.zeros((0, 2))] * 3
    assert MIN_APART == 0.3
    assert np.array_equal(reseat_positions(pos, np.zeros(5), sightings), pos)


def test_refine_puts_a_robot_fitted_out_of_place_back() -> None:
    _, recs = _dense_fleet(5)
    pf = build_poses(recs)
    k = int(np.argmax([r.count for r in recs]))
    if pf.ids[k] == pf.frame_robot:
        k = (k + 1) % len(pf.ids)
    pos = pf.positions.copy()
    pos[k] += [0.7, -0.7]  # ~1 m off, as a wrong pairing placed robot 36 (50 NAOs, seed 12)
    wrong = evaluate_poses(pf.ids, pf.measurements, pos, pf.headings, pf.frame_robot)
    assert not wrong.consistent
    fixed = refine_poses(wrong, recs)
    assert fixed.consistent
    assert np.allclose(fixed.positions, pf.positions, atol=0.05)


#: 4 × 4 lattice, 1 m, with a vacancy at (2, 2); every robot sees those within 1.5 m
LATTICE = np.array([[x, y] for y in range(4) for x in range(4) if (x, y) != (2, 2)], float)


def _near_sightings(pos: np.ndarray) -> list[np.ndarray]:
    out = []
    for k in range(pos.shape[0]):
        w = np.delete(pos, k, axis=0) - pos[k]
        out.append(w[np.hypot(*w.T) <= 1.5])
    return out


def test_seen_counts_by_hand() -> None:
    sightings = _near_sightings(LATTICE)
    seen = seen_counts(LATTICE, np.zeros(len(LATTICE)), sightings)
    assert seen[0] == 3  # the corner (0, 0) is seen by (1, 0), (0, 1), (1, 1)
    assert seen.tolist() == [len(v) for v in sightings]  # seeing is mutual here


def test_a_robot_on_the_wrong_lattice_spot_is_unseen_and_moved_back() -> None:
    # robot 0 (the corner) fitted on the vacancy: its 3 sightings land there too (on
    # (3, 2), (2, 3), (3, 3)), but nobody's sighting lands on it
    sightings = _near_sightings(LATTICE)
    pos = LATTICE.copy()
    pos[0] = [2.0, 2.0]
    psi = np.zeros(len(pos))
    assert seen_counts(pos, psi, sightings)[0] == 0
    out = reseat_positions(pos, psi, sightings)
    assert np.array_equal(out, LATTICE)
    records = [NeighborRecord(k + 1, v) for k, v in enumerate(sightings)]
    ids = tuple(range(1, len(pos) + 1))
    wrong = evaluate_poses(ids, [], pos, psi, 1)
    right = evaluate_poses(ids, [], LATTICE, psi, 1)
    assert not mostly_land(wrong, records) and mostly_land(right, records)


def _record(rid: int, vecs: np.ndarray) -> NeighborRecord:
    return NeighborRecord(rid, np.asarray(vecs, dtype=np.float64).reshape(-1, 2))


def test_junk_between_robots_is_dropped_for_a_sound_owner() -> None:
    ids = tuple(range(9))
    vecs = _sightings(GRID, 0, 0.0)  # robot 0 at (0, 0) sees the 8 others
    junk = np.array([[0.5, 1.0]])  # two NAOs seen as one, half-way between 3 and 4
    rec = _record(0, np.vstack([vecs, junk]))
    found = identify_sightings(ids, GRID, np.zeros(9), [rec], {(0, 8): 4})
    assert [(a, t) for _, a, t in found] == [(a, a + 1) for a in range(8)]


def test_a_suspect_owner_keeps_its_pairing() -> None:
    ids = tuple(range(9))
    vecs = _sightings(GRID, 0, 0.0, scale=1.4)  # most land on nobody
    rec = _record(0, vecs)
    paired = {(0, a): a + 1 for a in range(8)}
    found = identify_sightings(ids, GRID, np.zeros(9), [rec], paired)
    assert {(a, t) for _, a, t in found} == {(a, a + 1) for a in range(8)}


def test_two_sightings_of_one_robot_keep_the_nearer() -> None:
    ids = tuple(range(9))
    rec = _record(0, np.array([[1.1, 0.0], [1.02, 0.0], [0.0, 1.0]]))
    found = identify_sightings(ids, GRID, np.zeros(9), [rec], {(0, 0): 1})
    assert found == [(0, 1, 1), (0, 2, 3)]


def _dense_fleet(seed: int, n: int = 30) -> tuple[np.ndarray, list[NeighborRecord]]:
    rng = np.random.default_rng(seed)
    pos = sim_layout(rng, n)
    recs = unaligned_records(
        list(range(1, n + 1)), pos, np.full(n, math.pi / 2), rng, 0.03, math.radians(2)
    )
    return pos, recs


def test_refine_turns_a_robot_fitted_backwards_round() -> None:
    _, recs = _dense_fleet(5)
    pf = build_poses(recs)
    assert pf.consistent and float(np.max(np.abs(pf.headings))) < math.radians(3)
    k = int(np.argmax([r.count for r in recs]))  # a well-seen robot, fitted backwards
    psi = pf.headings.copy()
    psi[k] = math.pi
    wrong = evaluate_poses(pf.ids, pf.measurements, pf.positions, psi, pf.frame_robot)
    assert not wrong.consistent
    fixed = refine_poses(wrong, recs)
    assert fixed.consistent
    assert float(np.max(np.abs(fixed.headings))) < math.radians(3)
    assert np.allclose(fixed.positions, pf.positions, atol=0.05)


def test_merged_detections_in_a_dense_fleet_still_give_the_true_frame() -> None:
    """A robot that sees two close NAOs as one (between them) and misses both: its junk
    sighting can pair with a neighbour's sighting of someone else. The frame is still the
    truth (0.1 m, 3°), with nobody left out."""
    pos, recs = _dense_fleet(8, 40)
    out = []
    for rec in recs:
        own = pos[rec.robot_id - 1]
        d = np.hypot(*(pos - own).T)
        nb = rec.neighbours.copy()
        # merge the robot's two nearest seen neighbours that are < 1 m apart into one
        seen = [j for j in np.argsort(d) if 0.5 <= d[j] <= 3.0]
        pairs = [
            (a, b)
            for a in seen[:4]
            for b in seen[:4]
            if a < b and np.hypot(*(pos[a] - pos[b])) < 1.0
        ]
        if pairs and rec.robot_id % 2 == 0:
            a, b = pairs[0]
            ia = int(np.argmin(np.hypot(*(nb - (pos[a] - own)).T)))
            ib = int(np.argmin(np.hypot(*(nb - (pos[b] - own)).T)))
            nb[ia] = (nb[ia] + nb[ib]) / 2
            nb = np.delete(nb, ib, axis=0)
        out.append(NeighborRecord(rec.robot_id, nb))
    ff = fleet_frame(out, 0.35)
    assert "identified where they land" in ff.reason
    assert ff.excluded == ()
    truth = pos - pos[ff.frame_robot - 1]
    assert np.allclose(ff.positions, truth[[i - 1 for i in ff.ids]], atol=0.1)
    assert float(np.max(np.abs(ff.headings))) < math.radians(3)


@settings(max_examples=5, deadline=None)
@given(st.randoms(use_true_random=False))
def test_shuffled_records_refine_bit_identically(rnd) -> None:  # type: ignore[no-untyped-def]
    _, recs = _dense_fleet(5, 20)
    pf = build_poses(recs)
    psi = pf.headings.copy()
    psi[3] += math.pi
    wrong = evaluate_poses(pf.ids, pf.measurements, pf.positions, psi, pf.frame_robot)
    a = refine_poses(wrong, recs)
    shuffled = list(recs)
    rnd.shuffle(shuffled)
    b = refine_poses(wrong, shuffled)
    assert np.array_equal(a.positions, b.positions) and np.array_equal(a.headings, b.headings)


def _landing_by_definition(
    pos: np.ndarray, owner: int, points: np.ndarray, dist: np.ndarray
) -> list[int]:
    """landing's rule worked point by point: the nearest robot other than the owner, within
    the gate, with the next one at least AMBIGUITY times farther."""
    out = []
    for p, d in zip(points, dist, strict=True):
        r = [(float(np.hypot(*(p - q))), j) for j, q in enumerate(pos) if j != owner]
        r.sort()
        near, j = r[0] if r else (math.inf, -1)
        second = r[1][0] if len(r) > 1 else math.inf
        out.append(j if near <= float(gate(d)) and second >= AMBIGUITY * near else -1)
    return out


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(2, 12), st.integers(1, 6))
def test_landing_and_the_votes_counts_follow_the_definition(seed: int, n: int, m: int) -> None:
    """landing (a k-d tree), and _landings and _seen_on (every candidate at once), against
    the rule worked one point at a time (continuous coordinates: no distance sits on a
    gate or an ambiguity ratio, where rounding could decide)."""
    rng = np.random.default_rng(seed)
    pos = rng.uniform(-2.0, 2.0, size=(n, 2))
    k = int(rng.integers(0, n))
    vecs = rng.uniform(-1.5, 1.5, size=(m, 2))
    dist = np.hypot(*vecs.T)
    cands = rng.uniform(-2.0, 2.0, size=(5, 2))
    for c in cands:
        assert landing(pos, k, c + vecs, dist).tolist() == _landing_by_definition(
            pos, k, c + vecs, dist
        )
    got = _landings(pos, k, cands[:, None, :] + vecs[None, :, :], dist)
    want = [sum(h >= 0 for h in _landing_by_definition(pos, k, c + vecs, dist)) for c in cands]
    assert got.tolist() == want
    pts = rng.uniform(-2.0, 2.0, size=(8, 2))
    pd = rng.uniform(0.3, 2.0, size=8)
    seen = _seen_on(pos, k, cands, pts, pd)
    for c, count in zip(cands, seen.tolist(), strict=True):
        moved = pos.copy()
        moved[k] = c  # k standing at c; the points' owner is none of the robots
        hits = _landing_by_definition(moved, -1, pts, pd)
        assert count == sum(h == k for h in hits)


def _reseat_positions_every_candidate(
    positions: np.ndarray, headings: np.ndarray, sightings: list[np.ndarray]
) -> np.ndarray:
    """reseat_positions with every candidate's landings counted (no bound): the reference."""
    out = np.array(positions, dtype=np.float64)
    placed = [_place(out[k], float(headings[k]), v) for k, v in enumerate(sightings)]
    dists = [np.hypot(v[:, 0], v[:, 1]) for v in sightings]
    unseen = seen_counts(out, headings, sightings) == 0
    firm = np.array([v.shape[0] < MIN_SIGHTINGS or (
        2 * int(_landings(out, k, placed[k][None], dists[k])[0]) >= v.shape[0] and not unseen[k])
        for k, v in enumerate(sightings)], dtype=bool)  # fmt: skip
    for k, vecs in enumerate(sightings):
        if firm[k]:
            continue
        dist = dists[k]
        now = int(_landings(out, k, placed[k][None], dist)[0])
        turned = _place(np.zeros(2), float(headings[k]), vecs)
        others = np.delete(np.arange(out.shape[0]), k)
        cand = (out[others][None, :, :] - turned[:, None, :]).reshape(-1, 2)
        solid = out[others][firm[others]]
        if solid.shape[0]:
            gap = np.hypot(
                cand[:, None, 0] - solid[None, :, 0], cand[:, None, 1] - solid[None, :, 1]
            )
            cand = cand[np.min(gap, axis=1) >= MIN_APART]
        if cand.shape[0] == 0:
            continue
        own = _landings(out, k, cand[:, None, :] + turned[None, :, :], dist)
        pts = np.concatenate([placed[j] for j in range(len(sightings)) if j != k])
        pd = np.concatenate([dists[j] for j in range(len(sightings)) if j != k])
        seen = _seen_on(out, k, np.vstack([out[k][None], cand]), pts, pd)
        seen_now, seen_c = int(seen[0]), seen[1:]
        shift = np.hypot(cand[:, 0] - out[k, 0], cand[:, 1] - out[k, 1])
        best = int(np.lexsort((np.arange(cand.shape[0]), shift, -(own + seen_c)))[0])
        gain = int(own[best] + seen_c[best]) - (now + seen_now)
        if (
            own[best] >= RESEAT_SHARE * vecs.shape[0]
            and gain >= RESEAT_GAIN
            and seen_c[best] >= seen_now
        ):
            out[k] = cand[best]
            placed[k] = _place(out[k], float(headings[k]), vecs)
            firm[k] = True
    return out


def _messy_room(seed: int, n: int, off: int) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """A dense room's fitted poses with ``off`` robots misplaced or turned, and noisy
    sightings, some missed: robots for the vote, with candidates tied or near the gate."""
    rng = np.random.default_rng(seed)
    side = 0.8 * math.sqrt(n)
    pos = rng.uniform(0.0, side, size=(n, 2))
    psi = rng.uniform(-math.pi, math.pi, n)
    sightings = []
    for k in range(n):
        w = np.delete(pos, k, axis=0) - pos[k]
        w = w[(np.hypot(*w.T) < 3.5) & (rng.random(n - 1) < 0.8)]
        w = w @ rot(-psi[k]).T
        sightings.append(w * (1.0 + rng.normal(0.0, 0.03, (len(w), 1))))
    fitted, heads = pos.copy(), psi.copy()
    for k in rng.choice(n, size=min(off, n), replace=False):
        if rng.random() < 0.5:
            fitted[k] += rng.normal(0.0, 0.8, 2)
        else:
            heads[k] += rng.uniform(-math.pi, math.pi)
    return fitted, heads, sightings


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(2, 30), st.integers(0, 6))
def test_the_landing_bound_is_never_below_the_count(seed: int, n: int, off: int) -> None:
    """own_bound, against every candidate's landings counted (_landings)."""
    pos, psi, sightings = _messy_room(seed, n, off)
    for k in range(n):
        turned = _place(np.zeros(2), float(psi[k]), sightings[k])
        dist = np.hypot(*sightings[k].T)
        cand = (np.delete(pos, k, axis=0)[None, :, :] - turned[:, None, :]).reshape(-1, 2)
        count = _landings(pos, k, cand[:, None, :] + turned[None, :, :], dist)
        assert np.all(own_bound(pos, k, turned, dist) >= count)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(2, 40), st.integers(0, 8))
def test_reseated_positions_are_those_of_every_candidate_counted(
    seed: int, n: int, off: int
) -> None:
    """The vote on positions counts only the candidates its bound leaves in the running:
    the same positions, bit for bit, as counting every candidate."""
    pos, psi, sightings = _messy_room(seed, n, off)
    got = reseat_positions(pos, psi, sightings)
    assert got.tobytes() == _reseat_positions_every_candidate(pos, psi, sightings).tobytes()


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(8, 30), st.integers(0, 3))
def test_the_candidates_left_uncounted_cannot_have_the_most(seed: int, n: int, slack: int) -> None:
    """_counted_where_needed with any bound at or above the counts (looser bounds count more
    candidates, past its first share): every candidate it counts has its exact count, and
    every one it leaves out has a bound plus its extra below the best found."""
    pos, psi, sightings = _messy_room(seed, n, 4)
    rng = np.random.default_rng(seed)
    for k in range(n):
        turned = _place(np.zeros(2), float(psi[k]), sightings[k])
        dist = np.hypot(*sightings[k].T)
        cand = (np.delete(pos, k, axis=0)[None, :, :] - turned[:, None, :]).reshape(-1, 2)
        if cand.shape[0] == 0:
            continue
        count = _landings(pos, k, cand[:, None, :] + turned[None, :, :], dist)
        bound = count + rng.integers(0, slack + 1, cand.shape[0])
        extra = rng.integers(0, 4, cand.shape[0])
        counter = partial(_position_landings, pos, k, cand, turned, dist)
        got = _counted_where_needed(counter, bound, extra)
        done = got >= 0
        assert np.array_equal(got[done], count[done])
        best = int(np.max(count + extra))
        assert best == int(np.max(got[done] + extra[done]))
        assert np.all(bound[~done] + extra[~done] < best)


def _reseat_headings_every_candidate(
    positions: np.ndarray, headings: np.ndarray, sightings: list[np.ndarray]
) -> np.ndarray:
    """reseat_headings with every candidate heading's landings counted: the reference."""
    out = np.array(headings, dtype=np.float64)
    for k, vecs in enumerate(sightings):
        m = vecs.shape[0]
        if m < MIN_SIGHTINGS:
            continue
        dist = np.hypot(vecs[:, 0], vecs[:, 1])
        now = int(np.sum(landing(positions, k, _place(positions[k], out[k], vecs), dist) >= 0))
        if 2 * now >= m:
            continue
        rel = positions - positions[k]
        rng = np.hypot(rel[:, 0], rel[:, 1])
        close = np.abs(rng[None, :] - dist[:, None]) <= gate(dist)[:, None]
        close[:, k] = False
        a_idx, t_idx = np.nonzero(close)
        if a_idx.size == 0:
            continue
        cand = wrap_angle(
            np.arctan2(rel[t_idx, 1], rel[t_idx, 0]) - np.arctan2(vecs[a_idx, 1], vecs[a_idx, 0])
        )
        placed = np.stack([_place(positions[k], float(h), vecs) for h in cand])
        counts = _landings(positions, k, placed, dist)
        turn = np.abs(wrap_angle(cand - out[k]))
        best = int(np.lexsort((np.arange(cand.size), turn, -counts))[0])
        if counts[best] >= max(RESEAT_SHARE * m, now + RESEAT_GAIN):
            out[k] = float(cand[best])
    return out


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(2, 30), st.integers(0, 6))
def test_the_heading_bound_is_never_below_the_count(seed: int, n: int, off: int) -> None:
    """heading_bound, against the landings counted at every heading that puts a sighting
    on a robot (the vote's candidates, where the arcs' ends lie) and at random ones."""
    pos, _, sightings = _messy_room(seed, n, off)
    rng = np.random.default_rng(seed)
    for k in range(n):
        vecs = sightings[k]
        if vecs.shape[0] == 0:
            continue
        dist = np.hypot(*vecs.T)
        rel = np.delete(pos, k, axis=0) - pos[k]
        exact = (
            np.arctan2(rel[:, 1], rel[:, 0])[None, :] - np.arctan2(vecs[:, 1], vecs[:, 0])[:, None]
        )
        heads = wrap_angle(np.concatenate([exact.ravel(), rng.uniform(-math.pi, math.pi, 50)]))
        placed = np.stack([_place(pos[k], float(h), vecs) for h in heads])
        assert np.all(heading_bound(pos, k, vecs, heads) >= _landings(pos, k, placed, dist))


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(2, 40), st.integers(0, 8))
def test_reseated_headings_are_those_of_every_candidate_counted(
    seed: int, n: int, off: int
) -> None:
    """The vote on headings counts only the candidates its bound leaves in the running, and
    none when no heading can land enough: the same headings as counting every candidate."""
    pos, psi, sightings = _messy_room(seed, n, off)
    got = reseat_headings(pos, psi, sightings)
    assert got.tobytes() == _reseat_headings_every_candidate(pos, psi, sightings).tobytes()
