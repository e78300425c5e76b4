"""Wrong pairings dropped over several rounds (:func:`pose_check.drop_wrong_pairings`)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from agent.core.formation.frame import pose_check
from agent.core.formation.frame.pose_check import drop_wrong_pairings
from agent.core.formation.frame.poses import PoseFrame, PoseMeasurement, fit_poses
from tests.formation.pose_fleets import rot

SIDE = 6  # a 6 × 6 grid, 0.8 m apart: 36 NAOs, ~300 pairs within 3 m
NOISE = 0.04  # σ of each sighting, per metre of distance


def noisy_grid(seed: int, noise: float = NOISE) -> tuple[PoseFrame, np.ndarray]:
    """Every pair within 3 m seen both ways with ``noise``·d Gaussian noise: no faulty
    robot and no wrong pairing, only the tail of the noise on long pairs. Returns the fit
    and the true positions (row k: robot k + 1)."""
    rng = np.random.default_rng(seed)
    grid = np.array([[x, y] for x in range(SIDE) for y in range(SIDE)], dtype=float)
    pos = 0.8 * grid + rng.normal(0.0, 0.05, grid.shape)
    n = len(pos)
    psi = rng.uniform(-0.1, 0.1, n)
    meas = []
    for a, b in itertools.combinations(range(n), 2):
        if np.linalg.norm(pos[b] - pos[a]) > 3.0:
            continue
        for o, t in ((a, b), (b, a)):
            v = rot(-psi[o]) @ (pos[t] - pos[o])
            v = v + rng.normal(0.0, noise * np.linalg.norm(v), 2)
            meas.append(PoseMeasurement(o + 1, t + 1, v))
    return fit_poses(tuple(range(1, n + 1)), meas), pos


def dropped(reason: str) -> list[str]:
    return reason.split("misfit pair(s) ")[1].split(" (")[0].split(", ")


def worst_error(fit: PoseFrame, truth: np.ndarray) -> float:
    """Largest distance of a fitted start from the truth after the best rigid motion."""
    a = fit.positions - fit.positions.mean(axis=0)
    b = truth - truth.mean(axis=0)
    u, _, vt = np.linalg.svd(a.T @ b)
    return float(np.max(np.hypot(*(a @ (u @ vt) - b).T)))


@pytest.mark.parametrize("seed", [32, 51, 98])
def test_rounds_drop_the_noise_tail_and_keep_one_rounds_answer(seed: int) -> None:
    """Seeds worked by search: one isolated misfit pair or two (scores 1.03–1.29), and
    once they are dropped the refit moves another long pair just over the tolerance.
    One round gives up; three drop 3–4 pairs in all, each round's isolated, and the fit is
    consistent and true. Whatever one round accepts, three accept identically."""
    fit, truth = noisy_grid(seed)
    assert not fit.consistent
    one = drop_wrong_pairings(fit)
    three = drop_wrong_pairings(fit, rounds=3)
    if one is not None:
        assert three is not None and three.reason == one.reason
        np.testing.assert_array_equal(three.poses.positions, one.poses.positions)
    assert three is not None, "three rounds leave a misfit"
    assert three.named == () and three.poses.consistent
    budget = max(2, int(pose_check.MAX_DROPPED_SHARE * len(fit.pairs)))
    assert 1 <= len(dropped(three.reason)) <= budget
    assert worst_error(three.poses, truth) < 0.25
    assert worst_error(fit, truth) < 0.25


def test_several_rounds_help_somewhere() -> None:
    """Known answer: on the three seeds one round leaves a misfit pair at least once."""
    assert any(drop_wrong_pairings(noisy_grid(s)[0]) is None for s in (32, 51, 98))


def test_rounds_stop_at_the_budget(monkeypatch: pytest.MonkeyPatch) -> None:
    """With the share at 0 the budget is two pairs: no answer names more."""
    monkeypatch.setattr(pose_check, "MAX_DROPPED_SHARE", 0.0)
    for seed in (32, 51, 98):
        three = drop_wrong_pairings(noisy_grid(seed)[0], rounds=3)
        assert three is None or len(dropped(three.reason)) <= 2
    assert drop_wrong_pairings(noisy_grid(51)[0], rounds=3) is None  # 51 needs four


def test_no_misfit_no_verdict_and_a_robot_misfit_twice_is_no_wrong_pairing() -> None:
    """Exact sightings: nothing to drop. One grossly wrong sighting (robot 1 sees the far
    corner, 36, at 0.7 m): an isolated misfit pair, dropped. A second one on robot 1
    (of robot 31): robot 1 misfits twice, which is a fault, not a wrong pairing."""
    fit, _ = noisy_grid(32, noise=0.0)
    assert fit.consistent
    assert drop_wrong_pairings(fit, rounds=3) is None

    def wrong(*targets: int) -> PoseFrame:
        extra = [PoseMeasurement(1, t, np.array([0.5, 0.5])) for t in targets]
        return fit_poses(fit.ids, [*fit.measurements, *extra], fit.frame_robot)

    once = drop_wrong_pairings(wrong(36), rounds=3)
    assert once is not None and once.poses.consistent and dropped(once.reason) == ["1-36"]
    assert drop_wrong_pairings(wrong(36, 31), rounds=3) is None


def test_rounds_below_one_are_refused() -> None:
    fit, _ = noisy_grid(32)
    with pytest.raises(ValueError, match="rounds must be at least 1"):
        drop_wrong_pairings(fit, rounds=0)
