"""Robust Levenberg–Marquardt (agent/core/formation/frame/robust_lm.py): known answers against
scipy's ``least_squares(loss="soft_l1")``, robustness to an outlier, determinism, and one
test per error branch."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import least_squares
from scipy.sparse import csr_matrix, diags

from agent.core.formation.frame.robust_lm import (
    _Damped,
    _row_scaled,
    minimise,
    normal_equations,
    soft_l1_cost,
)


def _line(xs: np.ndarray, ys: np.ndarray):  # type: ignore[no-untyped-def]
    a = np.stack([xs, np.ones_like(xs)], axis=1)
    return (lambda p: a @ p - ys), (lambda p: csr_matrix(a))


def test_cost_by_hand() -> None:
    # ρ(z) = 2(√(1+z) − 1); ½ Σ ρ(f²) = Σ √(1+f²) − 1: f = (0, √3) -> 0 + (2 − 1)
    assert soft_l1_cost(np.array([0.0, np.sqrt(3.0)])) == pytest.approx(1.0)


def test_linear_fit_matches_scipy_soft_l1() -> None:
    rng = np.random.default_rng(3)
    xs = np.linspace(0.0, 5.0, 30)
    ys = 0.7 * xs - 1.2 + rng.normal(0, 0.5, xs.size)
    fun, jac = _line(xs, ys)
    ours, _ = minimise(fun, jac, np.zeros(2))
    ref = least_squares(
        fun, np.zeros(2), loss="soft_l1", f_scale=1.0, xtol=1e-14, ftol=1e-14, gtol=1e-14
    )
    assert np.allclose(ours, ref.x, atol=1e-7)


def test_one_gross_outlier_barely_moves_the_fit() -> None:
    xs = np.linspace(0.0, 5.0, 21)
    ys = 2.0 * xs + 1.0
    ys[10] += 100.0
    fun, jac = _line(xs, ys)
    robust, _ = minimise(fun, jac, np.zeros(2))
    plain = np.linalg.lstsq(np.stack([xs, np.ones_like(xs)], 1), ys, rcond=None)[0]
    assert np.allclose(robust, [2.0, 1.0], atol=0.1)
    assert abs(plain[1] - 1.0) > 3.0  # what a plain least-squares fit makes of it


def test_nonlinear_known_answer() -> None:
    # f(x) = (x0² − 4, x0·x1 − 6): the root (2, 3) from (1, 1)
    def fun(x: np.ndarray) -> np.ndarray:
        return np.array([x[0] ** 2 - 4.0, x[0] * x[1] - 6.0])

    def jac(x: np.ndarray) -> csr_matrix:
        return csr_matrix(np.array([[2 * x[0], 0.0], [x[1], x[0]]]))

    x, it = minimise(fun, jac, np.array([1.0, 1.0]))
    assert np.allclose(x, [2.0, 3.0], atol=1e-8)
    assert 0 < it < 200


@settings(max_examples=25, deadline=None)
@given(st.lists(st.floats(-10, 10), min_size=4, max_size=12), st.floats(-5, 5))
def test_deterministic_and_never_worse_than_the_start(ys: list[float], x0: float) -> None:
    xs = np.arange(len(ys), dtype=np.float64)
    fun, jac = _line(xs, np.array(ys))
    start = np.array([x0, 0.0])
    a, _ = minimise(fun, jac, start)
    b, _ = minimise(fun, jac, start)
    assert np.array_equal(a, b)
    assert soft_l1_cost(fun(a)) <= soft_l1_cost(fun(start)) + 1e-12


def test_nothing_to_fit_returns_the_start() -> None:
    x, it = minimise(lambda x: np.zeros(0), lambda x: csr_matrix((0, 2)), np.array([1.0, 2.0]))
    assert np.array_equal(x, [1.0, 2.0]) and it == 0


def test_a_singular_problem_stops_at_the_start() -> None:
    # the residual does not depend on x: no step lowers the cost
    x, _ = minimise(lambda x: np.array([1.0]), lambda x: csr_matrix((1, 1)), np.array([0.5]))
    assert np.array_equal(x, [0.5])


def test_non_finite_start_is_refused() -> None:
    fun, jac = _line(np.arange(3.0), np.zeros(3))
    with pytest.raises(ValueError, match="start is not finite"):
        minimise(fun, jac, np.array([np.nan, 0.0]))


def test_non_finite_residuals_at_the_start_are_refused() -> None:
    with pytest.raises(ValueError, match="residuals at the start"):
        minimise(lambda x: np.array([np.inf]), lambda x: csr_matrix((1, 1)), np.array([0.0]))


ROOT = Path(__file__).resolve().parents[3]
#: a pose-graph-like problem of 50 robots (147 unknowns, ~3 000 residuals), solved in a
#: fresh interpreter; prints the result's bytes
_SCRIPT = """
import hashlib, numpy as np
from scipy.sparse import csr_matrix, diags
from agent.core.formation.frame.robust_lm import minimise
rng = np.random.default_rng(7)
n, k = 147, 3000
rows = np.repeat(np.arange(k), 4)
cols = rng.integers(0, n, 4 * k)
vals = rng.normal(0.0, 1.0, 4 * k)
a = csr_matrix((vals, (rows, cols)), shape=(k, n))
truth = rng.normal(0.0, 1.0, n)
b = a @ truth + rng.standard_cauchy(k) * 0.01
x, _ = minimise(lambda x: np.sin(a @ x) - np.sin(b), lambda x: csr_matrix(a.multiply(np.cos(a @ x)[:, None])), np.zeros(n))
# and with Newton's steps near the minimum: Σ u_k ∇²f_k = Aᵀ diag(−u·sin(Ax)) A
curv = lambda x, u: (a.T @ diags(-u * np.sin(a @ x)) @ a).tocsc()
y, _ = minimise(lambda x: np.sin(a @ x) - np.sin(b), lambda x: csr_matrix(a.multiply(np.cos(a @ x)[:, None])), np.zeros(n), curv)
print(hashlib.sha256(x.tobytes() + y.tobytes()).hexdigest())
"""


def test_the_result_does_not_depend_on_the_blas_threads() -> None:
    """Identical agents must plan bit-identical plans on any host (docs/design.md §9): with a
    dense LAPACK solve, one and two OpenBLAS threads gave different last bits, and the
    50-NAO harness's evaluator a different plan digest than the agents."""
    out = []
    for threads in ("1", "2"):
        env = dict(os.environ, OPENBLAS_NUM_THREADS=threads, OMP_NUM_THREADS=threads)
        done = subprocess.run(
            [sys.executable, "-c", _SCRIPT], env=env, capture_output=True, text=True,
            timeout=300, check=True, cwd=ROOT,
        )  # fmt: skip
        out.append(done.stdout.strip())
    assert out[0] == out[1] and len(out[0]) == 64


def _same(a: Any, b: Any) -> bool:
    """The same entries at the same places (each made canonical: what SuperLU and the
    products read)."""
    a, b = a.copy(), b.copy()
    a.sum_duplicates()
    b.sum_duplicates()
    return all(getattr(a, k).tobytes() == getattr(b, k).tobytes()
               for k in ("indptr", "indices", "data"))  # fmt: skip


@settings(max_examples=80, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    rows=st.integers(1, 12),
    cols=st.integers(1, 6),
    zeros=st.booleans(),
    lam=st.floats(1e-12, 1e12),
)
def test_the_weighted_and_damped_matrices_are_the_products_bit_for_bit(
    seed: int, rows: int, cols: int, zeros: bool, lam: float
) -> None:
    """``diags(w) @ j`` and ``(h + diags(λd)).tocsc()`` as taken without the products: the
    same entries (explicit zeros in ``j`` and missing diagonals in ``h`` included)."""
    rng = np.random.default_rng(seed)
    dense = rng.normal(size=(rows, cols)) * (rng.random((rows, cols)) < 0.5)
    j = csr_matrix(dense)
    if zeros and j.nnz:
        j.data[rng.random(j.nnz) < 0.3] = 0.0  # explicit zeros, as a mask row's without a mask
    w = rng.uniform(0.1, 1.0, rows)
    assert _same(_row_scaled(j, w), diags(w) @ j)
    h = (j.T @ (diags(w) @ j)).tocsc()
    d = np.maximum(h.diagonal(), 1e-12)
    want = (h + diags(lam * d)).tocsc()
    assert _same(_Damped(h.copy())(lam * d), want)


def test_a_jacobian_with_an_entry_given_twice_is_weighted_as_the_product() -> None:
    """Two entries at one place: the product adds them weighted one at a time."""
    j = csr_matrix((np.array([0.1, 0.7, 0.3]), np.array([0, 0, 1]), np.array([0, 2, 3])), (2, 2))
    assert not j.has_canonical_format
    w = np.array([1.0 / 3.0, 0.9])
    got, want = _row_scaled(j, w), diags(w) @ j
    assert got.toarray().tobytes() == want.toarray().tobytes()


def _products(j: Any, w: np.ndarray, f: np.ndarray) -> tuple[Any, np.ndarray]:
    """``JᵀWJ`` (sorted) and ``JᵀWf`` by the sparse products themselves."""
    jw = _row_scaled(j, w)
    h = (j.T @ jw).tocsc()
    h.sort_indices()
    return h, np.asarray(jw.T @ f, dtype=np.float64).reshape(-1)


@settings(max_examples=200, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    rows=st.integers(1, 30),
    cols=st.integers(1, 9),
    zeros=st.booleans(),
    whole=st.booleans(),
)
def test_the_normal_equations_are_the_products_bit_for_bit(
    seed: int, rows: int, cols: int, zeros: bool, whole: bool
) -> None:
    """``JᵀWJ`` and ``JᵀWf`` without the sparse products: the same entries at the same
    places (explicit zeros of J, rows weighted 0 and sums that cancel to 0 included), and
    the pattern reused for a second Jacobian of the same places."""
    rng = np.random.default_rng(seed)
    dense = rng.normal(size=(rows, cols)) * (rng.random((rows, cols)) < 0.4)
    if whole:
        dense = np.round(dense)  # small integers: entries of JᵀWJ that cancel exactly
    j = csr_matrix(dense)
    if zeros and j.nnz:
        j.data[rng.random(j.nnz) < 0.3] = 0.0  # explicit zeros, as a mask row's without a mask
    w = rng.uniform(0.0, 1.0, rows) * (rng.random(rows) < 0.9)
    f = rng.normal(size=rows)
    h, g, pattern = normal_equations(j, w, f)
    want_h, want_g = _products(j, w, f)
    assert _same(h, want_h) and h.has_sorted_indices and g.tobytes() == want_g.tobytes()
    j2 = j.copy()
    j2.data = rng.normal(size=j.nnz)
    h2, g2, again = normal_equations(j2, w, f, pattern)
    want_h2, want_g2 = _products(j2, w, f)
    assert again is pattern and _same(h2, want_h2) and g2.tobytes() == want_g2.tobytes()


def test_a_jacobian_of_other_places_gets_its_own_pattern() -> None:
    a = csr_matrix(np.array([[1.0, 0.0], [2.0, 3.0]]))
    b = csr_matrix(np.array([[1.0, 4.0], [0.0, 3.0]]))
    w, f = np.array([0.5, 0.25]), np.array([1.0, -2.0])
    _, _, pattern = normal_equations(a, w, f)
    h, g, other = normal_equations(b, w, f, pattern)
    assert other is not pattern
    want_h, want_g = _products(b, w, f)
    assert _same(h, want_h) and g.tobytes() == want_g.tobytes()


def test_a_jacobian_not_canonical_takes_the_products() -> None:
    j = csr_matrix((np.array([0.1, 0.7, 0.3]), np.array([0, 0, 1]), np.array([0, 2, 3])), (2, 2))
    w, f = np.array([1.0 / 3.0, 0.9]), np.array([0.5, 2.0])
    h, g, pattern = normal_equations(j, w, f)
    want_h, want_g = _products(j, w, f)
    assert pattern is None and _same(h, want_h) and g.tobytes() == want_g.tobytes()


def test_newton_steps_near_the_minimum_reach_it_in_fewer_iterations() -> None:
    """With the residuals' curvature, the fit ends where the damped steps alone head for
    (robust_lm's Newton steps, begun near the minimum), in fewer iterations."""
    rng = np.random.default_rng(5)
    t = np.linspace(0.0, 4.0, 60)
    y = 2.0 * np.exp(-0.7 * t) + rng.normal(0.0, 0.05, t.size)
    y[::9] += 3.0  # gross outliers: the loss bends where the damped steps under-weight it

    def fun(p: np.ndarray) -> np.ndarray:
        return np.asarray((p[0] * np.exp(-p[1] * t) - y) / 0.05)

    def jac(p: np.ndarray) -> csr_matrix:
        e = np.exp(-p[1] * t)
        return csr_matrix(np.stack([e, -p[0] * t * e], axis=1) / 0.05)

    def curvature(p: np.ndarray, u: np.ndarray) -> Any:
        e = np.exp(-p[1] * t)
        d01, d11 = float(np.sum(u * -t * e)), float(np.sum(u * p[0] * t * t * e))
        return csr_matrix(np.array([[0.0, d01], [d01, d11]]) / 0.05).tocsc()

    start = np.array([1.0, 0.2])
    plain, it_plain = minimise(fun, jac, start)
    newton, it_newton = minimise(fun, jac, start, curvature)
    assert np.allclose(newton, plain, atol=1e-6)
    assert soft_l1_cost(fun(newton)) <= soft_l1_cost(fun(plain)) + 1e-9
    assert it_newton < it_plain
    again, _ = minimise(fun, jac, start, curvature)
    assert np.array_equal(again, newton)


def test_a_singular_newton_hessian_gives_way_to_the_damped_step() -> None:
    """A curvature that makes the Hessian singular: SuperLU refuses it, the damped steps
    go on and reach the minimum."""
    rng = np.random.default_rng(3)
    xs = np.linspace(0.0, 5.0, 30)
    ys = 0.7 * xs - 1.2 + rng.normal(0, 0.5, xs.size)
    ys[::7] += 20.0
    fun, jac = _line(xs, ys)
    plain, _ = minimise(fun, jac, np.zeros(2))

    def cancel(p: np.ndarray, u: np.ndarray) -> Any:
        f = fun(p)
        w = 1.0 / np.sqrt(1.0 + f * f)
        h3, _, _ = normal_equations(jac(p), w * w * w, f)
        calls.append(p)
        return -h3  # JᵀW³J + this: no entry left

    calls: list[np.ndarray] = []

    x, _ = minimise(fun, jac, np.zeros(2), cancel)
    assert np.allclose(x, plain, atol=1e-6)
    assert calls  # Newton steps were taken
