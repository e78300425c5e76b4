"""The masks' test of "every robot set down aligned" that skips the aligned candidates
(fleet_frame.masks_reject_alignment, docs/design.md §9): its false-alarm bound, its power,
and what it skips."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.formation.frame import fleet_frame as ff
from agent.core.formation.frame.fleet_frame import (
    ALIGNED_ALPHA,
    _candidates,
    alignment_log_ratio,
    masks_reject_alignment,
)
from agent.core.formation.frame.neighbour_check import DEFAULT_EPSILON, identify_neighbours
from agent.core.perception.sighting_noise import SightingNoise, shipped_noise
from tests.formation.pose_fleets import sim_layout, unaligned_records

NOISE = shipped_noise()
THRESHOLD = math.log(1.0 / ALIGNED_ALPHA)


def _aligned_masks(rng: np.random.Generator, n: int, noise: SightingNoise) -> np.ndarray:
    """n mask misses drawn from the mask model f (the null hypothesis)."""
    u = rng.random(n)
    bump = rng.normal(0.0, noise.sigma_mask, n)
    side = np.where(rng.random(n) < 0.5, -math.pi / 2, math.pi / 2)
    return np.where(u < noise.w0, bump,
                    np.where(u < noise.w0 + noise.w90, side + bump,
                             rng.uniform(-math.pi / 2, math.pi / 2, n)))  # fmt: skip


def test_the_ratio_has_expectation_one_under_alignment() -> None:
    """E_f[g/f] = ∫ g = 1 over a period: Markov's inequality bounds the false alarms."""
    d = np.linspace(-math.pi / 2, math.pi / 2, 200_001)[:-1]
    ratio = np.exp([alignment_log_ratio(np.array([x]), NOISE) for x in d[::50]])
    f = NOISE.mask_density(d[::50])
    assert float(np.sum(ratio * f) * math.pi / len(f)) == pytest.approx(1.0, abs=1e-4)


@pytest.mark.parametrize("n", [1, 10, 100, 1000])
def test_aligned_masks_do_not_reject_alignment(n: int) -> None:
    rng = np.random.default_rng(n)
    stats = [alignment_log_ratio(_aligned_masks(rng, n, NOISE), NOISE) for _ in range(2000)]
    assert max(stats) < THRESHOLD
    # the statistic falls with the masks: −0.76 a mask on average
    assert float(np.mean(stats)) == pytest.approx(-0.76 * n, rel=0.1, abs=0.5)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(40, 300))
def test_masks_of_robots_set_down_at_random_reject_alignment(seed: int, n: int) -> None:
    rng = np.random.default_rng(seed)
    # each mask of a pair of robots whose heading difference is uniform, plus the mask noise
    d = _aligned_masks(rng, n, NOISE) + rng.uniform(-math.pi / 2, math.pi / 2, n)
    assert alignment_log_ratio(d, NOISE) >= THRESHOLD


def test_no_masks_say_nothing() -> None:
    assert alignment_log_ratio(np.zeros(0), NOISE) == 0.0
    rng = np.random.default_rng(0)
    pos = sim_layout(rng, 6)
    recs = unaligned_records(list(range(1, 7)), pos, rng.uniform(-math.pi, math.pi, 6),
                             masks=False)  # fmt: skip
    assert not masks_reject_alignment(identify_neighbours(recs, DEFAULT_EPSILON), NOISE)


def _room(seed: int, n: int, turned: bool) -> list:  # type: ignore[type-arg]
    rng = np.random.default_rng(seed)
    pos = sim_layout(rng, n)
    heads = rng.uniform(-math.pi, math.pi, n) if turned else np.full(n, math.pi / 2)
    return unaligned_records(list(range(1, n + 1)), pos, heads, rng, 0.02, math.radians(1.0))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_fleet_set_down_turned_skips_the_aligned_candidates(
    seed: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Set down at random, the aligned candidates build nothing (the papers' model is
    never fitted); set down aligned, the papers' model is the first candidate."""
    papers: list[int] = []
    real = ff._papers_poses

    def counted(graph):  # type: ignore[no-untyped-def]
        papers.append(1)
        return real(graph)

    monkeypatch.setattr(ff, "_papers_poses", counted)
    turned = _room(seed, 20, True)
    assert masks_reject_alignment(identify_neighbours(turned, DEFAULT_EPSILON), NOISE)
    cands = _candidates(turned, DEFAULT_EPSILON)
    assert [c.build() for c in cands[:2]] == [None, None] and papers == []
    aligned = _room(seed, 20, False)
    assert not masks_reject_alignment(identify_neighbours(aligned, DEFAULT_EPSILON), NOISE)
    first = _candidates(aligned, DEFAULT_EPSILON, NOISE)[0].build()
    assert first is not None and first[0].aligned and papers == [1]
