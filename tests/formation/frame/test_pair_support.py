"""Loop-consistency support of candidate pairs (agent/core/formation/frame/pair_support.py):
known answers by hand, the windowed count against a brute force over all of j's sightings
(exactly, ties included) and against a plain loop over candidates with a k-d tree (an
independent algorithm), the brute-force path for far or non-finite input, and one
test per error branch."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from agent.core.formation.frame import pair_support
from agent.core.formation.frame.pair_support import support_one_side

EPS = 0.35
REL = 0.08


def rot(a: float, v: tuple[float, float]) -> tuple[float, float]:
    c, s = math.cos(a), math.sin(a)
    return (c * v[0] - s * v[1], s * v[0] + c * v[1])


def loop_reference(
    src: np.ndarray,
    dst: np.ndarray,
    turn: np.ndarray,
    owner: np.ndarray,
    vecs: np.ndarray,
    epsilon: float,
    rel_tol: float,
) -> np.ndarray:
    """One candidate at a time, a k-d tree per robot (an algorithm of its own)."""
    out = np.zeros(src.shape[0], dtype=np.int64)
    for t in range(src.shape[0]):
        oi, oj = owner[src[t]], owner[dst[t]]
        others = np.flatnonzero((owner == oi) & (np.arange(owner.size) != src[t]))
        mine = np.flatnonzero(owner == oj)
        if others.size == 0 or mine.size < 2:
            continue
        rel = vecs[others] - vecs[src[t]]
        c, s = math.cos(-turn[t]), math.sin(-turn[t])
        moved = np.stack([rel[:, 0] * c - rel[:, 1] * s, rel[:, 0] * s + rel[:, 1] * c], axis=1)
        dist, k = cKDTree(vecs[mine]).query(moved)
        tol = 0.5 * epsilon + rel_tol * np.hypot(rel[:, 0], rel[:, 1])
        out[t] = int(np.sum((dist <= tol) & (mine[k] != dst[t])))
    return out


def brute_reference(
    src: np.ndarray,
    dst: np.ndarray,
    turn: np.ndarray,
    owner: np.ndarray,
    vecs: np.ndarray,
    epsilon: float,
    rel_tol: float,
) -> np.ndarray:
    """One candidate at a time, every sighting of j looked at: np.argmin of d² (the first
    of equal ones), with the module's float operations, so the counts must agree exactly."""
    out = np.zeros(src.shape[0], dtype=np.int64)
    for t in range(src.shape[0]):
        others = np.flatnonzero((owner == owner[src[t]]) & (np.arange(owner.size) != src[t]))
        mine = np.flatnonzero(owner == owner[dst[t]])
        if others.size == 0 or mine.size < 2:
            continue
        rx = vecs[others, 0] - vecs[src[t], 0]
        ry = vecs[others, 1] - vecs[src[t], 1]
        c, s = np.cos(-turn[t : t + 1]), np.sin(-turn[t : t + 1])
        mx, my = rx * c - ry * s, rx * s + ry * c
        dx = mx[:, None] - vecs[mine, 0][None, :]
        dy = my[:, None] - vecs[mine, 1][None, :]
        d2 = dx * dx + dy * dy
        k = np.argmin(d2, axis=1)
        tol = 0.5 * epsilon + rel_tol * np.sqrt(rx * rx + ry * ry)
        near = np.sqrt(d2[np.arange(others.size), k]) <= tol
        out[t] = int(np.sum(near & (mine[k] != dst[t])))
    return out


def triangle(psi_j: float) -> tuple[np.ndarray, np.ndarray]:
    """Robots i at (0, 0), j at (1, 0), c at (0, 1) in the world; i's frame is the world's,
    j's is turned by ``psi_j``. Rows: i sees j, i sees c, j sees i, j sees c."""

    def in_j(v: tuple[float, float]) -> tuple[float, float]:
        return rot(-psi_j, v)

    vecs = np.array([(1.0, 0.0), (0.0, 1.0), in_j((-1.0, 0.0)), in_j((-1.0, 1.0))])
    return np.array([0, 0, 1, 1]), vecs


@pytest.mark.parametrize("psi_j", [0.0, math.pi / 2, -2.0, math.pi])
def test_a_closed_triangle_counts_one_from_each_side(psi_j: float) -> None:
    owner, vecs = triangle(psi_j)
    turn = np.array([psi_j])
    assert support_one_side(np.array([0]), np.array([2]), turn, owner, vecs, EPS, REL).tolist() == [
        1
    ]
    assert support_one_side(
        np.array([2]), np.array([0]), -turn, owner, vecs, EPS, REL
    ).tolist() == [1]


def test_the_wrong_turn_closes_nothing() -> None:
    owner, vecs = triangle(math.pi / 2)
    out = support_one_side(np.array([0]), np.array([2]), np.array([0.0]), owner, vecs, EPS, REL)
    assert out.tolist() == [0]  # (−1, 1) unturned lands 1.4 m from j's (1, 1)


def test_a_hit_on_the_candidates_own_sighting_does_not_count() -> None:
    # i: a = (1, 0), k = (0.05, 0): k − a = (−0.95, 0) lands on j's sighting of i itself
    owner = np.array([0, 0, 1, 1])
    vecs = np.array([(1.0, 0.0), (0.05, 0.0), (-1.0, 0.0), (3.0, 3.0)])
    out = support_one_side(np.array([0]), np.array([2]), np.array([0.0]), owner, vecs, EPS, REL)
    assert out.tolist() == [0]


def test_robots_with_a_single_sighting_close_nothing() -> None:
    owner = np.array([0, 1, 1])
    vecs = np.array([(1.0, 0.0), (-1.0, 0.0), (-1.0, 1.0)])
    out = support_one_side(np.array([0]), np.array([1]), np.array([0.0]), owner, vecs, EPS, REL)
    assert out.tolist() == [0]
    empty = np.zeros(0, dtype=np.int64)
    assert support_one_side(empty, empty, np.zeros(0), owner, vecs, EPS, REL).shape == (0,)


@st.composite
def sighting_sets(draw: st.DrawFn) -> tuple[np.ndarray, ...]:
    n = draw(st.integers(2, 6))
    counts = draw(st.lists(st.integers(1, 6), min_size=n, max_size=n))
    owner = np.repeat(np.arange(n), counts)
    coord = st.floats(-3.0, 3.0, allow_nan=False, width=32)
    flat = draw(st.lists(coord, min_size=2 * owner.size, max_size=2 * owner.size))
    # a lattice of 0.1 m makes exact ties between equidistant sightings likely
    vecs = np.round(np.array(flat, dtype=np.float64).reshape(-1, 2), 1)
    pairs = [(a, b) for a in range(owner.size) for b in range(owner.size) if owner[a] != owner[b]]
    chosen = draw(st.lists(st.sampled_from(pairs), min_size=1, max_size=40))
    src = np.array([a for a, _ in chosen], dtype=np.int64)
    dst = np.array([b for _, b in chosen], dtype=np.int64)
    turns = draw(
        st.lists(
            st.sampled_from([0.0, math.pi / 2, -math.pi, 0.3, -2.1]),
            min_size=len(chosen),
            max_size=len(chosen),
        )
    )
    return src, dst, np.array(turns), owner, vecs


@settings(max_examples=300, deadline=None)
@given(sighting_sets())
def test_the_vectorised_count_is_the_loop_over_candidates(case: tuple[np.ndarray, ...]) -> None:
    src, dst, turn, owner, vecs = case
    got = support_one_side(src, dst, turn, owner, vecs, EPS, REL)
    want = loop_reference(src, dst, turn, owner, vecs, EPS, REL)
    # exact ties between two of j's sightings may go either way in the k-d tree; the
    # count differs only where such a tie involves the candidate's own sighting
    assert np.array_equal(got, want) or _only_ties_differ(case, got, want)


@st.composite
def tie_prone_sets(draw: st.DrawFn) -> tuple[np.ndarray, ...]:
    """Sightings on a lattice of 0.25 m (exact in binary) and quarter turns: many moved
    sightings at exactly equal distances from two of j's, and on distance-band edges."""
    n = draw(st.integers(2, 5))
    counts = draw(st.lists(st.integers(1, 7), min_size=n, max_size=n))
    owner = np.repeat(np.arange(n), counts)
    cells = draw(st.lists(st.integers(-12, 12), min_size=2 * owner.size, max_size=2 * owner.size))
    vecs = 0.25 * np.array(cells, dtype=np.float64).reshape(-1, 2)
    pairs = [(a, b) for a in range(owner.size) for b in range(owner.size) if owner[a] != owner[b]]
    chosen = draw(st.lists(st.sampled_from(pairs), min_size=1, max_size=40))
    turns = draw(
        st.lists(
            st.sampled_from([0.0, math.pi / 2, -math.pi / 2, math.pi, 0.7]),
            min_size=len(chosen),
            max_size=len(chosen),
        )
    )
    src = np.array([a for a, _ in chosen], dtype=np.int64)
    dst = np.array([b for _, b in chosen], dtype=np.int64)
    return src, dst, np.array(turns), owner, vecs


@settings(max_examples=300, deadline=None)
@given(st.one_of(sighting_sets(), tie_prone_sets()), st.sampled_from([0.35, 0.5, 1.0]))
def test_the_windowed_count_is_the_brute_force_exactly(
    case: tuple[np.ndarray, ...], epsilon: float
) -> None:
    src, dst, turn, owner, vecs = case
    got = support_one_side(src, dst, turn, owner, vecs, epsilon, REL)
    assert np.array_equal(got, brute_reference(src, dst, turn, owner, vecs, epsilon, REL))


def test_the_windowed_count_is_the_brute_force_on_a_dense_random_set() -> None:
    rng = np.random.default_rng(11)
    owner = np.repeat(np.arange(12), rng.integers(1, 12, size=12))
    vecs = rng.uniform(-3, 3, size=(owner.size, 2))
    src, dst = np.nonzero(owner[:, None] != owner[None, :])
    turn = rng.uniform(-math.pi, math.pi, size=src.size)
    got = support_one_side(src, dst, turn, owner, vecs, EPS, REL)
    assert got.sum() > 0
    assert np.array_equal(got, brute_reference(src, dst, turn, owner, vecs, EPS, REL))


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
@pytest.mark.parametrize("scale", [1e120, 1e160])
def test_far_sightings_take_the_brute_force(scale: float) -> None:
    rng = np.random.default_rng(5)
    owner = np.repeat(np.arange(4), 3)
    vecs = rng.uniform(-3, 3, size=(owner.size, 2))
    vecs[4] *= scale  # beyond HUGE; at 1e160 the squares overflow to inf
    src, dst = np.nonzero(owner[:, None] != owner[None, :])
    turn = rng.uniform(-math.pi, math.pi, size=src.size)
    got = support_one_side(src, dst, turn, owner, vecs, EPS, REL)
    assert np.array_equal(got, brute_reference(src, dst, turn, owner, vecs, EPS, REL))


@st.composite
def free_sets(draw: st.DrawFn) -> tuple[np.ndarray, ...]:
    """Any turns (also far outside (−π, π]), sightings at the origin or on top of each
    other, candidates given twice, and robots of one sighting."""
    n = draw(st.integers(1, 5))
    counts = draw(st.lists(st.integers(1, 8), min_size=n, max_size=n))
    counts[0] = max(counts[0], 2)  # two sightings at least: a candidate to draw
    owner = np.repeat(np.arange(n), counts)
    cell = st.one_of(st.integers(-8, 8).map(lambda c: 0.25 * c), st.floats(-4.0, 4.0))
    flat = draw(st.lists(cell, min_size=2 * owner.size, max_size=2 * owner.size))
    vecs = np.array(flat, dtype=np.float64).reshape(-1, 2)
    pairs = [(a, b) for a in range(owner.size) for b in range(owner.size) if a != b]
    chosen = draw(st.lists(st.sampled_from(pairs), min_size=1, max_size=30))
    angle = st.one_of(
        st.floats(-50.0, 50.0), st.sampled_from([0.0, math.pi, -math.pi, 2 * math.pi])
    )
    turns = draw(st.lists(angle, min_size=len(chosen), max_size=len(chosen)))
    src = np.array([a for a, _ in chosen], dtype=np.int64)
    dst = np.array([b for _, b in chosen], dtype=np.int64)
    return src, dst, np.array(turns), owner, vecs


@settings(max_examples=300, deadline=None)
@given(free_sets(), st.sampled_from([0.05, 0.35, 2.0]), st.sampled_from([0.0, 0.08, 0.5]))
def test_the_arc_count_is_the_brute_force_for_any_turn_and_tolerance(
    case: tuple[np.ndarray, ...], epsilon: float, rel_tol: float
) -> None:
    src, dst, turn, owner, vecs = case
    got = support_one_side(src, dst, turn, owner, vecs, epsilon, rel_tol)
    assert np.array_equal(got, brute_reference(src, dst, turn, owner, vecs, epsilon, rel_tol))


@settings(max_examples=50, deadline=None)
@given(sighting_sets(), st.randoms(use_true_random=False))
def test_shuffled_candidates_get_their_own_counts(
    case: tuple[np.ndarray, ...], rnd: random.Random
) -> None:
    src, dst, turn, owner, vecs = case
    whole = support_one_side(src, dst, turn, owner, vecs, EPS, REL)
    order = list(range(src.size))
    rnd.shuffle(order)
    perm = np.array(order)
    got = support_one_side(src[perm], dst[perm], turn[perm], owner, vecs, EPS, REL)
    assert np.array_equal(got, whole[perm])


def test_a_dense_fleet_of_fifty_counts_as_the_brute_force() -> None:
    # fifty robots in a room, each seeing its neighbours within 3.5 m, turned at random:
    # the windows and arcs of a real fleet, against the brute force (a sample of it)
    rng = np.random.default_rng(7)
    world = rng.uniform(0.0, 9.0, size=(50, 2))
    psi = rng.uniform(-math.pi, math.pi, size=50)
    rows, owner = [], []
    for i in range(50):
        for j in range(50):
            d = world[j] - world[i]
            if i != j and np.hypot(*d) < 3.5:
                rows.append(rot(-psi[i], (d[0] + rng.normal(0, 0.03), d[1] + rng.normal(0, 0.03))))
                owner.append(i)
    vecs, own = np.array(rows), np.array(owner)
    dist = np.hypot(vecs[:, 0], vecs[:, 1])
    src, dst = np.nonzero(
        (own[:, None] < own[None, :]) & (np.abs(dist[:, None] - dist[None, :]) < 0.3)
    )
    bearing = np.arctan2(vecs[:, 1], vecs[:, 0])
    turn = np.pi - np.mod(np.pi - (bearing[src] - bearing[dst] + np.pi), 2 * np.pi)
    got = support_one_side(src, dst, turn, own, vecs, EPS, REL)
    assert got.sum() > 1000
    pick = rng.choice(src.size, size=3000, replace=False)
    want = brute_reference(src[pick], dst[pick], turn[pick], own, vecs, EPS, REL)
    assert np.array_equal(got[pick], want)


def test_a_non_finite_turn_takes_the_brute_force() -> None:
    owner, vecs = triangle(math.pi / 2)
    src, dst = np.array([0, 0]), np.array([2, 2])
    turn = np.array([math.pi / 2, math.nan])
    got = support_one_side(src, dst, turn, owner, vecs, EPS, REL)
    assert got.tolist() == [1, 0]
    assert np.array_equal(got, brute_reference(src, dst, turn, owner, vecs, EPS, REL))


def _only_ties_differ(case: tuple[np.ndarray, ...], got: np.ndarray, want: np.ndarray) -> bool:
    """Every differing count has a moved sighting equally near dst and another of j's."""
    src, dst, turn, owner, vecs = case
    for t in np.flatnonzero(got != want):
        others = np.flatnonzero((owner == owner[src[t]]) & (np.arange(owner.size) != src[t]))
        mine = np.flatnonzero(owner == owner[dst[t]])
        rel = vecs[others] - vecs[src[t]]
        c, s = math.cos(-turn[t]), math.sin(-turn[t])
        moved = np.stack([rel[:, 0] * c - rel[:, 1] * s, rel[:, 0] * s + rel[:, 1] * c], axis=1)
        d = np.hypot(*(moved[:, None, :] - vecs[mine][None, :, :]).transpose(2, 0, 1))
        at_dst = d[:, mine == dst[t]][:, 0]
        tie = np.isclose(d, at_dst[:, None], rtol=1e-9, atol=1e-12) & (mine != dst[t])[None, :]
        if not np.any(tie.any(axis=1) & np.isclose(at_dst, d.min(axis=1), rtol=1e-9, atol=1e-12)):
            return False
    return True


def test_small_chunks_give_the_same_counts(monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(3)
    owner = np.repeat(np.arange(8), rng.integers(2, 7, size=8))
    vecs = rng.uniform(-3, 3, size=(owner.size, 2))
    src, dst = np.nonzero(owner[:, None] != owner[None, :])
    turn = rng.uniform(-math.pi, math.pi, size=src.size)
    whole = support_one_side(src, dst, turn, owner, vecs, EPS, REL)
    monkeypatch.setattr(pair_support, "CHUNK_BLOCKS", 7)
    assert np.array_equal(support_one_side(src, dst, turn, owner, vecs, EPS, REL), whole)
    assert np.array_equal(whole, loop_reference(src, dst, turn, owner, vecs, EPS, REL))
    assert np.array_equal(whole, brute_reference(src, dst, turn, owner, vecs, EPS, REL))


@pytest.mark.parametrize(
    ("src", "dst", "turn", "owner", "vecs", "match"),
    [
        ([0], [1, 2], [0.0], [0, 1, 1], np.zeros((3, 2)), "src, dst and turn"),
        ([0], [1], [0.0], [0, 1], np.zeros((3, 2)), "owner must be"),
        ([0], [5], [0.0], [0, 1, 1], np.zeros((3, 2)), "out of range"),
        ([-1], [1], [0.0], [0, 1, 1], np.zeros((3, 2)), "out of range"),
        ([0], [1], [0.0], [1, 0, 1], np.zeros((3, 2)), "ascending"),
    ],
)
def test_bad_input_is_refused(
    src: list[int],
    dst: list[int],
    turn: list[float],
    owner: list[int],
    vecs: np.ndarray,
    match: str,
) -> None:
    with pytest.raises(ValueError, match=match):
        support_one_side(
            np.array(src), np.array(dst), np.array(turn), np.array(owner), vecs, EPS, REL
        )
