"""The bias tests of many robots fitted side by side (bias_test.bias_fits and its
_Batch, docs/design.md §9) against the definition: each robot's misfits and Jacobian are
its _Sightings.errors whitened, element for element, and each robot's fit is the
reference below (one robot at a time, iteratively reweighted Gauss-Newton, halving a step
until it lowers the cost), up to rounding; a robot's answer does not depend on which
others are fitted beside it."""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.formation.frame.faults.bias_test import (
    HALVINGS,
    LOSS_SCALE,
    MAX_ITER,
    MIN_OWN,
    MIN_SEEN,
    TOL,
    _Batch,
    _Sightings,
    _solve,
    bias_fit,
    bias_fits,
    cauchy_cost,
)
from agent.core.formation.frame.faults.fault_test import unpaired
from agent.core.formation.frame.neighbour_check import DEFAULT_EPSILON
from agent.core.formation.frame.pose_pairing import identify_pairs
from agent.core.formation.frame.poses import PoseFrame, PoseMeasurement, fit_from_graph
from agent.core.formation.frame.records import NeighborRecord
from agent.core.perception.sighting_noise import SightingNoise
from tests.formation.pose_fleets import fault, sim_layout, unaligned_records

NOISE = SightingNoise.synthetic(0.01, 0.02, math.radians(1.0))


@functools.cache
def _fleet(seed: int, n: int, kind: str) -> tuple[PoseFrame, tuple[NeighborRecord, ...]]:
    rng = np.random.default_rng(seed)
    ids = list(range(1, n + 1))
    recs = unaligned_records(ids, sim_layout(rng, n), rng.uniform(-math.pi, math.pi, n), rng,
                             0.02, math.radians(1.0))  # fmt: skip
    if kind:
        recs = [fault(r, kind) if r.robot_id == 3 else r for r in recs]
    return fit_from_graph(identify_pairs(recs, DEFAULT_EPSILON)), tuple(recs)


def _own_seen(
    poses: PoseFrame, robot: int, loose: np.ndarray | None
) -> tuple[list[PoseMeasurement | np.ndarray], list[PoseMeasurement]]:
    """``robot``'s own sightings (its loose ones last) and the others' of it, by (owner, target)."""
    ms = sorted((m for m in poses.measurements if robot in (m.owner, m.target)),
                key=lambda m: (m.owner, m.target))  # fmt: skip
    own: list[PoseMeasurement | np.ndarray] = [m for m in ms if m.owner == robot]
    if loose is not None:
        own += list(np.asarray(loose).reshape(-1, 2))
    return own, [m for m in ms if m.target == robot]


def _sightings(
    poses: PoseFrame, robot: int, loose: np.ndarray | None, elsewhere: np.ndarray | None = None
) -> _Sightings | None:
    own, seen = _own_seen(poses, robot, loose)
    if not own or not seen:
        return None
    return _Sightings(poses, robot, own, seen, NOISE, elsewhere)


# --- the reference: one robot, its definition -------------------------------------------


def _ref_fit(s: _Sightings, x0: np.ndarray, free: bool) -> tuple[np.ndarray, float]:
    s.free = free

    def res(x: np.ndarray) -> np.ndarray:
        return s.whiten(s.errors(x, False)[0])

    x = np.array(x0, dtype=np.float64)
    r = res(x)
    cost = float(cauchy_cost(r))
    f2 = LOSS_SCALE * LOSS_SCALE
    for _ in range(MAX_ITER):
        jac = s.errors(x, True)[1]
        assert jac is not None
        j = s.whiten(jac)
        jw = j * (1.0 / (1.0 + r * r / f2))[:, None]
        try:
            step = np.linalg.solve(jw.T @ j + 1e-9 * np.eye(len(x)), -(jw.T @ r))
        except np.linalg.LinAlgError:
            break
        for _ in range(HALVINGS):
            trial = x + step
            r_t = res(trial)
            c_t = float(cauchy_cost(r_t))
            if c_t <= cost:
                break
            step = step / 2.0
        else:
            break
        done = cost - c_t <= TOL * max(cost, 1.0)
        x, r, cost = trial, r_t, c_t
        if done:
            break
    return x, cost


def _ref_best(s: _Sightings, start: np.ndarray) -> tuple[np.ndarray, float]:
    x_a, c_a = _ref_fit(s, start, True)
    psi = float(x_a[2])
    scale, shift = (float(x_a[3]), x_a[4:6]) if len(x_a) > 3 else (1.0, np.zeros(2))
    hit = s._matched(0, x_a[:2], math.cos(psi), math.sin(psi), scale, shift)[: s.n_paired]
    if np.array_equal(hit, s.paired_to):
        return x_a, c_a
    x_p, _ = _ref_fit(s, start, False)
    x_b, c_b = _ref_fit(s, x_p, True)
    return (x_a, c_a) if c_a <= c_b else (x_b, c_b)


def _ref_statistic(
    poses: PoseFrame, robot: int, loose: np.ndarray | None
) -> tuple[float, int, int] | None:
    """Λ with the worst sighting set aside, and the sightings kept (None: too few)."""
    s = _sightings(poses, robot, loose)
    if s is None or s.n_own < MIN_OWN or len(s.v_all) - s.n_own < MIN_SEEN:
        return None
    x_h0, _ = _ref_best(s, s.x0)
    s.free = True
    r, k = s.whiten(s.errors(x_h0, False)[0]), len(s.v_all)
    worst = int(np.argmax(np.round(r[:k] ** 2 + r[k:] ** 2, 9)))
    own, seen = _own_seen(poses, robot, loose)
    n_own = len(own)
    own = [m for i, m in enumerate(own) if i != worst]
    seen = [m for i, m in enumerate(seen) if i != worst - n_own]
    if len(own) < MIN_OWN or len(seen) < MIN_SEEN:
        return None
    rest = _Sightings(poses, robot, own, seen, NOISE)
    x0, c0 = _ref_best(rest, x_h0)
    _, c1 = _ref_best(rest, np.concatenate([x0, [1.0, 0.0, 0.0]]))
    return max(0.0, 2.0 * (c0 - c1)), len(own), len(seen)


@pytest.mark.parametrize(("seed", "kind"), [(1, ""), (2, "scale"), (3, "shift"), (4, "rotate")])
def test_each_robot_s_statistic_is_its_own_fit_s(seed: int, kind: str) -> None:
    poses, recs = _fleet(seed, 8, kind)
    loose = unpaired(poses, recs)
    fits = bias_fits(poses, poses.ids, NOISE, 1.0, loose)
    assert list(fits) == list(poses.ids)
    for r in poses.ids:
        want = _ref_statistic(poses, r, loose.get(r))
        got = fits[r]
        if want is None:
            assert (got.statistic, got.p) == (0.0, 1.0)
            continue
        assert (got.own, got.seen) == want[1:]
        assert got.statistic == pytest.approx(want[0], rel=1e-7, abs=1e-7), r


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(1, 6), picks=st.lists(st.integers(1, 8), min_size=1, max_size=8))
def test_a_robot_s_fit_does_not_depend_on_who_is_fitted_beside_it(
    seed: int, picks: list[int]
) -> None:
    """Any subset, in any order (repeats too): each robot's answer is its fit alone's, up
    to rounding, and the answers come in the order asked."""
    poses, recs = _fleet(seed, 8, "scale" if seed % 2 else "")
    loose = unpaired(poses, recs)
    together = bias_fits(poses, picks, NOISE, 1.0, loose)
    assert list(together) == list(dict.fromkeys(picks))
    for r in picks:
        alone = bias_fit(poses, r, NOISE, 1.0, loose.get(r))
        got = together[r]
        assert (got.own, got.seen) == (alone.own, alone.seen)
        assert got.statistic == pytest.approx(alone.statistic, rel=1e-9, abs=1e-9)
        assert got.p == pytest.approx(alone.p, rel=1e-6, abs=1e-12)


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(1, 6),
    robots=st.lists(st.integers(1, 8), min_size=1, max_size=4, unique=True),
    step=st.lists(st.floats(-0.5, 0.5), min_size=6, max_size=6),
    biased=st.booleans(),
    free=st.booleans(),
    loose=st.booleans(),
)
def test_the_batch_s_misfits_and_jacobian_are_the_definitions_bit_for_bit(
    seed: int, robots: list[int], step: list[float], biased: bool, free: bool, loose: bool
) -> None:
    """Each robot's row of the batch's residuals and Jacobian holds ``whiten(errors(x))``
    (its misfits in its owner's frame, then whitened) in every bit, padded entries 0, at
    any pose and bias, every own sighting matched where it lands or the pairing kept."""
    poses, _ = _fleet(seed, 8, "scale" if seed % 2 else "")
    extra = np.array([[0.7, -0.4]]) if loose else None
    fits = [s for r in robots if (s := _sightings(poses, r, extra, np.array([[9.0, 9.0]])))]
    if not fits:
        return
    batch = _Batch(fits)
    x = np.array([f.x0 for f in fits]) + np.array(step[:3])
    if biased:
        x = np.concatenate([x, np.tile([1.0 + step[3], step[4], step[5]], (len(fits), 1))], 1)
    every = np.arange(len(fits))
    r, rel = batch.residuals(every, x, free)
    j = batch.jacobian(every, x, rel)
    ko, ks = batch.ko, batch.ks
    for k, f in enumerate(fits):
        f.free = free
        want_r = f.whiten(f.errors(x[k], False)[0])
        jac = f.errors(x[k], True)[1]
        assert jac is not None
        want_j = f.whiten(jac)
        n_own, n = f.n_own, len(f.v_all)
        rows = np.r_[0:n_own, ko : ko + n - n_own, ko + ks : ko + ks + n_own,
                     2 * ko + ks : 2 * ko + ks + n - n_own]  # fmt: skip
        assert r[k, rows].tobytes() == want_r.tobytes()
        assert np.array_equal(j[k, rows], want_j)  # 0.0 and -0.0 alike
        pad = np.setdiff1d(np.arange(r.shape[1]), rows)
        assert not r[k, pad].any() and not j[k, pad].any()


def test_a_robot_with_too_few_sightings_and_bad_input() -> None:
    poses, _ = _fleet(1, 8, "")
    fits = bias_fits(poses, [], NOISE, 1.0)
    assert fits == {}
    with pytest.raises(ValueError, match="has no pose"):
        bias_fits(poses, [1, 99], NOISE, 1.0)
    with pytest.raises(ValueError, match="bias_scale"):
        bias_fits(poses, [1], NOISE, -1.0)
    thin = dataclasses.replace(
        poses, measurements=tuple(m for m in poses.measurements if m.owner != 2)
    )
    got = bias_fits(thin, [2, 1], NOISE, 1.0)
    assert got[2].p == 1.0 and got[2].own == 0 and got[1].own > 0


def test_a_singular_robot_stops_and_the_others_go_on() -> None:
    """A robot whose normal equations cannot be solved keeps its start; the others' steps
    are each solved on their own."""
    normal = np.stack([np.eye(3), np.zeros((3, 3)), 2.0 * np.eye(3)])
    step, ok = _solve(normal, np.ones((3, 3)))
    assert ok.tolist() == [True, False, True]
    assert step[0].tolist() == [1.0, 1.0, 1.0] and step[2].tolist() == [0.5, 0.5, 0.5]


def test_the_batch_turns_by_the_floats_of_math() -> None:
    # the batch's cos ψ and sin ψ are math.cos and math.sin of each ψ, as a robot's own
    # fit (_Sightings.errors) takes them
    from agent.core.formation.frame.faults.bias_test import _cos_sin

    psi = np.random.default_rng(4).uniform(-40.0, 40.0, 300)
    c, s = _cos_sin(psi)
    assert c.shape == s.shape == (300, 1)
    assert c[:, 0].tolist() == [math.cos(v) for v in psi.tolist()]
    assert s[:, 0].tolist() == [math.sin(v) for v in psi.tolist()]
