"""Fitting the poses again from more than one start
(agent/core/formation/frame/multi_start.py)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.formation.frame import multi_start as ms
from agent.core.formation.frame import robust_lm
from agent.core.formation.frame.poses import (
    PoseFrame,
    _Problem,
    build_poses,
    evaluate_poses,
    fit_cost,
    fit_poses,
)
from tests.formation.frame.faults.test_fault_test import fleet


def _turned_start(good: PoseFrame, robot: int) -> tuple[np.ndarray, np.ndarray]:
    """``good``'s poses with ``robot`` turned half round (the frame robot: every other
    robot turned half round about it)."""
    pos, psi = good.positions.copy(), good.headings.copy()
    if robot == good.frame_robot:
        pos, psi = -pos, psi + math.pi
        psi[good.ids.index(robot)] = 0.0
    else:
        psi[good.ids.index(robot)] += math.pi
    return pos, (psi + math.pi) % (2 * math.pi) - math.pi


def _stuck(good: PoseFrame, robot: int) -> PoseFrame:
    """The fit of ``good``'s measurements from ``robot`` half turned round: a local
    minimum of the robust cost, half a turn from the truth."""
    wrong = fit_poses(good.ids, good.measurements, good.frame_robot, _turned_start(good, robot))
    k = good.ids.index(robot)
    if robot == good.frame_robot:
        k = (k + 1) % len(good.ids)  # the others are turned: look at one of them
    off = abs((wrong.headings[k] - good.headings[k] + math.pi) % (2 * math.pi) - math.pi)
    assert off > math.radians(170.0), "the turned start is not a local minimum here"
    return wrong


def _same(a: PoseFrame, b: PoseFrame) -> bool:
    return bool(
        np.allclose(a.positions, b.positions, atol=1e-6)
        and np.allclose(a.headings, b.headings, atol=1e-6)
    )


@pytest.mark.parametrize(("seed", "robot"), [(0, 3), (1, 8), (2, 5)])
def test_a_robot_fitted_half_turned_round_is_turned_back(seed: int, robot: int) -> None:
    good = build_poses(fleet(seed))
    wrong = _stuck(good, robot)
    back = ms.half_turned(wrong, robot)
    assert back is not None and _same(back, good)
    assert fit_cost(back) < fit_cost(wrong) / 10.0


def test_the_frame_robot_half_turned_round_is_turned_back() -> None:
    good = build_poses(fleet(0))
    wrong = _stuck(good, good.frame_robot)
    back = ms.half_turned(wrong, good.frame_robot)
    assert back is not None and _same(back, good)


def test_turning_a_well_fitted_robot_never_fits_better() -> None:
    good = build_poses(fleet(1))
    assert all(ms.half_turned(good, r) is None for r in good.ids)


def test_a_warm_start_half_a_turn_off_is_refitted_from_the_tree() -> None:
    good = build_poses(fleet(2))
    wrong = _stuck(good, 4)
    again = ms.refit(wrong, good.ids, good.measurements)
    assert again is not None and _same(again, good)


def test_refit_with_too_few_or_unconnected_robots_is_none() -> None:
    good = build_poses(fleet(0))
    assert ms.refit(good, good.ids[:1], good.measurements) is None
    robot = good.ids[-1]
    cut = [m for m in good.measurements if robot not in (m.owner, m.target)]
    assert ms.refit(good, good.ids, cut) is None  # robot no longer connected


def test_better_keeps_the_first_of_equal_costs() -> None:
    good = build_poses(fleet(0))
    twin = replace(good, positions=good.positions.copy())
    assert ms.better(good, twin) is good and ms.better(twin, good) is twin
    wrong = _stuck(good, 3)
    assert ms.better(wrong, good) is good and ms.better(good, wrong) is good


def test_half_turning_an_unknown_robot_is_refused() -> None:
    good = build_poses(fleet(0))
    with pytest.raises(ValueError, match="not among"):
        ms.half_turned(good, 99)


def test_poses_are_expressed_in_another_robots_frame() -> None:
    good = build_poses(fleet(0))
    other = good.ids[-1]
    pos, psi = ms.in_frame_of(good, good.ids, other)
    k = good.ids.index(other)
    assert np.allclose(pos[k], 0.0) and psi[k] == pytest.approx(0.0)
    moved = evaluate_poses(good.ids, good.measurements, pos, psi, other)
    # the same poses, moved: the soft-L1 loss acts per axis, so the cost is not exactly
    # invariant to the frame (which is why fits are only compared in one frame)
    assert fit_cost(moved) == pytest.approx(fit_cost(good), rel=1e-3)


@pytest.mark.parametrize(("seed", "robot"), [(0, 3), (1, 8), (2, 5)])
def test_a_robot_held_half_a_turn_off_fits_its_sightings_better_turned(
    seed: int, robot: int
) -> None:
    """The screen before a whole fit from the turned start: a robot stuck half a turn
    off fits its own sightings and the others' of it better turned, its pose alone
    refitted; a well-fitted robot never does, and no whole fit is then tried."""
    good = build_poses(fleet(seed))
    assert ms._turn_helps(_stuck(good, robot), robot)
    assert not any(ms._turn_helps(good, r) for r in good.ids if r != good.frame_robot)


def test_a_turn_that_does_not_help_the_robot_tries_no_whole_fit(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    good = build_poses(fleet(1))
    fits: list[int] = []
    real = ms.fit_poses

    def counted(*args, **kwargs):  # type: ignore[no-untyped-def]
        fits.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(ms, "fit_poses", counted)
    robot = next(r for r in good.ids if r != good.frame_robot)
    assert ms.half_turned(good, robot) is None and fits == []
    lonely = replace(good, measurements=tuple(m for m in good.measurements
                                              if robot not in (m.owner, m.target)))  # fmt: skip
    assert not ms._turn_helps(lonely, robot)  # no sighting of it: nothing to turn


def _alone_reference(prob: _Problem, x: np.ndarray, c: int, k: int, turn: float) -> float:
    """:func:`multi_start._alone` one entry of the normal equations at a time (each an
    ``np.sum`` of its own products): the numbers the fast path must give, bit for bit."""
    m = prob.m
    sign = (prob.t == k).astype(np.float64) - (prob.o == k)
    owner = prob.o == k

    def fun(y: np.ndarray) -> np.ndarray:
        z = x.copy()
        z[c : c + 3] = y
        return prob.fun(z)

    def jac(y: np.ndarray) -> np.ndarray:
        _, psi = prob.unpack(np.concatenate([x[:c], y, x[c + 3 :]]))
        cs, sn = math.cos(float(y[2])), math.sin(float(y[2]))
        delta = psi[prob.t] - psi[prob.o] - prob.mask_ref
        j = np.zeros((3 * m, 3))
        j[0 : 2 * m : 2, 0] = sign * prob.sp
        j[1 : 2 * m : 2, 1] = sign * prob.sp
        vx, vy = prob.v[:, 0], prob.v[:, 1]
        j[0 : 2 * m : 2, 2] = np.where(owner, (sn * vx + cs * vy) * prob.sp, 0.0)
        j[1 : 2 * m : 2, 2] = np.where(owner, -(cs * vx - sn * vy) * prob.sp, 0.0)
        j[2 * m :, 2] = sign * prob.sm * np.cos(2.0 * delta)
        return j

    def entries(jw: np.ndarray, j: np.ndarray) -> np.ndarray:
        return np.array([[float(np.sum(jw[:, a] * j[:, b])) for b in range(3)] for a in range(3)])

    def bend(y: np.ndarray, u: np.ndarray, f: np.ndarray) -> float:
        # Σ u ∂²f/∂ψ² of robot k's ψ: its own position rows bend, and every mask row (−4f)
        cs, sn = math.cos(float(y[2])), math.sin(float(y[2]))
        vx, vy = prob.v[:, 0], prob.v[:, 1]
        pos = u[0 : 2 * m : 2] * (cs * vx - sn * vy) + u[1 : 2 * m : 2] * (sn * vx + cs * vy)
        return float(np.sum(np.where(owner, pos * prob.sp, 0.0)) + np.sum(-4.0 * u[2 * m :]
                                                                           * f[2 * m :]))  # fmt: skip

    def solved(a: np.ndarray, g: np.ndarray) -> np.ndarray | None:
        try:
            return np.asarray(-np.linalg.solve(a, g))
        except np.linalg.LinAlgError:
            return None

    def better(
        y: np.ndarray, step: np.ndarray, cost: float, switch: float
    ) -> tuple[np.ndarray, np.ndarray, float, bool, bool] | None:
        """(y + step, its residuals, its cost, small, near) when the step lowers the cost."""
        f_new = fun(y + step)
        cost_new = robust_lm.soft_l1_cost(f_new)
        if not cost_new < cost:
            return None
        small = cost - cost_new <= ms.ALONE_FTOL * cost
        return y + step, f_new, cost_new, small, cost - cost_new <= switch * cost

    y = x[c : c + 3] + np.array([0.0, 0.0, turn])
    f = fun(y)
    cost = robust_lm.soft_l1_cost(f)
    lam = robust_lm.LAMBDA0
    near, switch = False, robust_lm.NEAR
    for _ in range(ms.ALONE_ITER):
        j = jac(y)
        w = 1.0 / np.sqrt(1.0 + f * f)
        jw = j / np.sqrt(1.0 + f * f)[:, None]
        h = entries(jw, j)
        g = np.array([float(np.sum(jw[:, a] * f)) for a in range(3)])
        if near:
            exact = entries(j * (w * w * w)[:, None], j)
            exact[2, 2] += bend(y, w * f, f)
            step = solved(exact, g)
            if step is not None:
                taken = better(y, step, cost, switch)
                if taken is not None:
                    y, f, cost, small, near = taken
                    if small:
                        break
                    continue
                if 0.0 < -0.5 * float(np.sum(g * step)) <= ms.ALONE_FTOL * cost:
                    break
            near, switch = False, switch * robust_lm.NEAR_TIGHTEN
        d = np.maximum(np.diag(h), 1e-12)
        while True:
            step = solved(h + np.diag(lam * d), g)
            if step is not None:
                taken = better(y, step, cost, switch)
                if taken is not None:
                    y, f, cost, small, near = taken
                    lam = max(lam / 3.0, 1e-12)
                    break
            lam *= 4.0
            if lam > robust_lm.LAMBDA_MAX:
                return cost
        if small:
            break
    return cost


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**16),
    n=st.integers(3, 12),
    turn=st.sampled_from([math.pi, 0.0, 1.3, -2.5]),
    kind=st.sampled_from(["", "rotate", "scale", "shift"]),
)
def test_one_robot_fitted_alone_is_the_reference_bit_for_bit(
    seed: int, n: int, turn: float, kind: str
) -> None:
    poses = build_poses(fleet(seed, n, kind, victim=2))
    for robot in poses.ids:
        if robot == poses.frame_robot:
            continue
        k = poses.ids.index(robot)
        mine = [m for m in poses.measurements if robot in (m.owner, m.target)]
        if not mine:
            continue
        prob = _Problem(poses.ids, mine, poses.ids.index(poses.frame_robot))
        x = prob.pack(poses.positions, poses.headings)
        c = int(prob.col[k])
        got, want = ms._alone(prob, x, c, k, turn), _alone_reference(prob, x, c, k, turn)
        assert np.float64(got).tobytes() == np.float64(want).tobytes()
