"""Robust Levenberg–Marquardt on sparse normal equations, for the pose fit of
:mod:`poses` (docs/design.md §9).

Minimises ``½ Σ ρ(f_k(x)²)`` with the soft-L1 loss ``ρ(z) = 2(√(1 + z) − 1)`` (the loss
``scipy.optimize.least_squares(loss="soft_l1", f_scale=1)`` uses, the same stationary
points), by iteratively re-weighted Gauss–Newton steps with Marquardt's damping:

    (JᵀWJ + λ·diag(JᵀWJ)) δ = −JᵀW f,   W = diag(ρ′(f²)) = diag(1/√(1 + f²)),

a step accepted when it lowers the cost (λ ÷ 3), refused otherwise (λ × 4). These steps
converge linearly: W under-weights the loss's bend (its curvature is ``ρ′ + 2ρ″f²``, not
``ρ′``): a fit of 50 NAOs from its spanning tree takes 110-200 of them alone, the last
hundred each lowering the cost by a constant fraction. So once an accepted step lowers
the cost by at most :data:`NEAR` of it (the fit is then in the basin of its minimum, where
the exact Hessian is positive definite), each iteration first tries Newton's step,
undamped, on the exact Hessian ``JᵀW³J + Σ_k ρ′_k f_k ∇²f_k``
(``W³ = diag((1 + f²)^(−3/2))``; the residuals' own curvature from the caller,
``curvature``): it converges quadratically
to the minimum the Gauss–Newton steps head for (the 50-NAO fits of
``tests/data/runs/n50_random_s1018.json``: the same minima, the frames planned on within
10⁻⁷ m of the damped steps' alone, in half the iterations). A Newton step that does not
lower the cost gives way to the damped step, and Newton is taken up again only once a step lowers the cost by
:data:`NEAR_TIGHTEN` times less; a refused Newton step whose model predicts a decrease
below :data:`FTOL` of the cost ends the fit (the cost cannot resolve it). Begun at 1e-3
of the cost, Newton leaves the basin of that fleet's sound fit from a plateau of small
Gauss–Newton steps, and its fault-free run leaves a sound robot out. Why not
``least_squares`` itself: its exact trust-region solver takes an SVD of the dense
Jacobian every iteration (3 000 × 147 at 50 NAOs: ~45 ms, ~2 s a fit), and its sparse
solver (LSMR) stopped at its budget short of the exact solver's minimum (robot 45 of the
50-NAO seed-11 records 3.6 m off). The normal equations here are (3N − 3)² and sparse:
a fit of 50 NAOs takes tens of milliseconds.

Deterministic: no randomness, a fixed iteration budget and fixed tolerances; the same
inputs give bit-identical outputs on one platform, whatever its BLAS threads: each step
is solved by SuperLU (``scipy.sparse.linalg.splu`` on the sparse damped system, or the
Hessian of a Newton step), which calls no threaded BLAS. A dense LAPACK solve
(``numpy.linalg.solve``) gave other last
bits with one OpenBLAS thread than with two, and at 50 NAOs the agents (one thread each)
and the harness's evaluator (two) planned different digests from the same records;
agents on hosts with other thread settings would have too. ``JᵀWJ`` and ``JᵀWf`` are
summed from the Jacobian's entries (:func:`normal_equations`): the very sums the sparse
products add, in their order, without building the products.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.sparse import csc_matrix, csr_matrix, diags
from scipy.sparse.linalg import splu

#: Iteration budget (accepted or refused steps).
MAX_ITER = 200
#: Stop when a step lowers the cost by less than this fraction of it ...
FTOL = 1e-12
#: ... or moves x by less than this (relative to |x| + XTOL).
XTOL = 1e-12
LAMBDA0 = 1e-3  #: initial damping
LAMBDA_MAX = 1e12  #: damping beyond which no step can lower the cost: stop
#: Newton steps begin once an accepted step lowers the cost by at most this fraction of it
#: (the fit is then near a minimum, where the exact Hessian is positive definite) ...
NEAR = 1e-6
#: ... and after a Newton step that does not lower the cost, once a step lowers it by this
#: much less again (Gauss–Newton steps in between)
NEAR_TIGHTEN = 0.1


def _row_scaled(j: csr_matrix, w: np.ndarray) -> csr_matrix:
    """``diags(w) @ j`` as that product leaves it: each entry times its row's weight,
    the entries that become 0 left out (the product keeps no zeros). What follows reads
    only the entries and their places, never their order in a row: the same bits. A
    matrix with an entry given twice is left to the product itself (it adds each weighted)."""
    if not j.has_canonical_format:
        return diags(w) @ j
    rows = np.repeat(np.arange(j.shape[0]), np.diff(j.indptr))
    out = csr_matrix((j.data * w[rows], j.indices.copy(), j.indptr.copy()), shape=j.shape)
    out.eliminate_zeros()
    return out


class _Normal:
    """``JᵀWJ`` (sorted CSC) and ``JᵀWf`` for every Jacobian of one sparsity pattern, as
    ``(j.T @ _row_scaled(j, w)).tocsc()`` and ``_row_scaled(j, w).T @ f`` leave them, to
    the bit, without building the sparse products: each entry of ``JᵀWJ`` is the sum,
    row by row of J in ascending order, of ``(jw)_rb · j_ra`` (what the product's SMMP
    loop adds, from 0), kept only when it is not 0 (as the product keeps no zeros); each
    of ``JᵀWf`` the sum, by row, of ``(jw)_rb · f_r``. ``np.bincount`` adds its weights
    one after the other in that order. A weighted entry that is 0 (an explicit zero of J,
    as a mask row's without a mask) adds nothing here either: those the product leaves
    out are weighted 0 before they are summed."""

    def __init__(self, j: csr_matrix) -> None:
        self.shape = j.shape
        self.indptr = j.indptr.copy()
        self.indices = j.indices.copy()
        n = j.shape[1]
        per = np.diff(self.indptr).astype(np.int64)
        self.rows = np.repeat(np.arange(j.shape[0]), per)
        # every (p, q) of one row of J, rows ascending: p the entry of JW (column b), q of J
        # (column a), for h[a, b]
        sq = per * per
        row = np.repeat(np.arange(per.size), sq)
        k = np.arange(int(sq.sum())) - np.repeat(np.cumsum(sq) - sq, sq)
        first = self.indptr[:-1].astype(np.int64)[row]
        self.p = first + k // per[row]
        self.q = first + k % per[row]
        slot = self.indices[self.p].astype(np.int64) * n + self.indices[self.q]
        uniq, self.slot = np.unique(slot, return_inverse=True)
        self.slots = uniq.size
        self.h_rows = (uniq % n).astype(np.int32)
        self.h_cols = (uniq // n).astype(np.int64)
        self.h_indptr = np.zeros(n + 1, dtype=np.int32)
        np.cumsum(np.bincount(self.h_cols, minlength=n), out=self.h_indptr[1:])

    def fits(self, j: csr_matrix) -> bool:
        """Whether ``j`` has this pattern (canonical CSR, the same places)."""
        return (
            j.shape == self.shape
            and np.array_equal(j.indptr, self.indptr)
            and np.array_equal(j.indices, self.indices)
        )

    def __call__(
        self, j: csr_matrix, w: np.ndarray, f: np.ndarray
    ) -> tuple[csc_matrix, np.ndarray]:
        jw = j.data * w[self.rows]  # as _row_scaled
        live = jw != 0
        every = bool(live.all())
        prod = jw[self.p] * j.data[self.q]
        if not every:
            prod[~live[self.p]] = 0.0
        sums = np.bincount(self.slot, weights=prod, minlength=self.slots)
        n = self.shape[1]
        keep = sums != 0
        if keep.all():
            h = csc_matrix((sums, self.h_rows.copy(), self.h_indptr.copy()), shape=(n, n))
        else:
            indptr = np.zeros(n + 1, dtype=np.int32)
            np.cumsum(np.bincount(self.h_cols[keep], minlength=n), out=indptr[1:])
            h = csc_matrix((sums[keep], self.h_rows[keep], indptr), shape=(n, n))
        h.has_sorted_indices = True
        gw = jw * f[self.rows]
        if not every:
            gw[~live] = 0.0
        g = np.bincount(self.indices, weights=gw, minlength=n)
        return h, g


def normal_equations(
    j: csr_matrix, w: np.ndarray, f: np.ndarray, normal: _Normal | None = None
) -> tuple[csc_matrix, np.ndarray, _Normal | None]:
    """(``JᵀWJ`` as CSC, ``JᵀWf``, the pattern to pass again): by :class:`_Normal` for a
    canonical CSR ``j`` (``normal`` reused while ``j`` keeps its pattern), else by the
    sparse products themselves; the same bits either way."""
    if isinstance(j, csr_matrix) and j.has_canonical_format:
        if normal is None or not normal.fits(j):
            normal = _Normal(j)
        h, g = normal(j, w, f)
        return h, g, normal
    jw = _row_scaled(j, w)
    h = (j.T @ jw).tocsc()
    g = np.asarray(jw.T @ f, dtype=np.float64).reshape(-1)
    return h, g, None


class _Damped:
    """``(h + diags(v)).tocsc()`` for one ``h`` and many ``v`` (Marquardt's λ changes,
    ``h`` does not): ``h``'s entries with ``v`` added on its diagonal, when ``h`` holds
    every diagonal entry (else the sum itself). The same entries and values as the sum
    (``h`` keeps no zeros, so ``h_ij + 0`` is ``h_ij``); SuperLU takes its input sorted."""

    def __init__(self, h: csc_matrix) -> None:
        self.h = h
        h.sort_indices()  # the same matrix, its rows in order in each column
        cols = np.repeat(np.arange(h.shape[1]), np.diff(h.indptr))
        self.diag = np.flatnonzero(h.indices == cols)
        self.full = self.diag.size == h.shape[0] == h.shape[1]

    def __call__(self, v: np.ndarray) -> csc_matrix:
        if not self.full:
            return (self.h + diags(v)).tocsc()
        data = self.h.data.copy()
        data[self.diag] = data[self.diag] + v
        out = csc_matrix((data, self.h.indices, self.h.indptr), shape=self.h.shape)
        out.has_sorted_indices = True
        return out


def soft_l1_cost(f: np.ndarray) -> float:
    """``½ Σ ρ(f²)`` with ``ρ(z) = 2(√(1 + z) − 1)``."""
    return float(np.sum(np.sqrt(1.0 + f * f) - 1.0))


def minimise(
    fun: Callable[[np.ndarray], np.ndarray],
    jac: Callable[[np.ndarray], csr_matrix],
    x0: np.ndarray,
    curvature: Callable[[np.ndarray, np.ndarray], csc_matrix] | None = None,
) -> tuple[np.ndarray, int]:
    """(x, iterations): the robust minimum reached from ``x0`` (module docstring).
    ``curvature(x, u)``: ``Σ_k u_k ∇²f_k`` at ``x`` (sparse, symmetric), for the Newton
    steps near the minimum (None: Gauss–Newton steps only).

    Raises ``ValueError`` for a non-finite start or residual at the start.
    """
    x = np.array(x0, dtype=np.float64)
    if not np.all(np.isfinite(x)):
        raise ValueError("start is not finite")
    f = fun(x)
    if not np.all(np.isfinite(f)):
        raise ValueError("residuals at the start are not finite")
    cost = soft_l1_cost(f)
    lam = LAMBDA0
    it = 0
    normal: _Normal | None = None
    near = False  # the last accepted step lowered the cost by at most `switch` of it
    switch = NEAR
    while it < MAX_ITER and x.size and f.size:
        j = jac(x)
        w = 1.0 / np.sqrt(1.0 + f * f)
        h, g, normal = normal_equations(j, w, f, normal)
        if near and curvature is not None:
            it += 1
            newton = _newton_step(j, w, f, normal, curvature(x, w * f), g)
            if newton is not None:
                step, predicted = newton
                better = _better(fun, x, step, cost, switch)
                if better is not None:
                    x, f, cost, done, near = better
                    if done:
                        return x, it
                    continue
                if 0.0 < predicted <= FTOL * cost:
                    return x, it  # the model's decrease is below the rounding of the cost
            near, switch = False, switch * NEAR_TIGHTEN
            if it >= MAX_ITER:
                break
        d = np.maximum(h.diagonal(), 1e-12)
        damp = _Damped(h)
        improved = False
        while it < MAX_ITER:
            it += 1
            a = damp(lam * d)
            try:
                step = -splu(a).solve(g)
            except RuntimeError:  # SuperLU: "Factor is exactly singular"
                lam *= 4.0
                if lam > LAMBDA_MAX:
                    return x, it
                continue
            better = _better(fun, x, step, cost, switch)
            if better is not None:
                x, f, cost, done, near = better
                lam = max(lam / 3.0, 1e-12)
                improved = True
                if done:
                    return x, it
                break
            lam *= 4.0
            if lam > LAMBDA_MAX:
                return x, it
        if not improved:
            break
    return x, it


def _better(
    fun: Callable[[np.ndarray], np.ndarray],
    x: np.ndarray,
    step: np.ndarray,
    cost: float,
    switch: float,
) -> tuple[np.ndarray, np.ndarray, float, bool, bool] | None:
    """A step taken, Newton's or damped: ``(x + step, its residuals, its cost, whether it
    ends the fit (:func:`_small`), whether it lowered the cost by at most ``switch`` of
    it)`` when it lowers the cost (a residual not finite costs ∞); None when it does not."""
    x_new = x + step
    f_new = fun(x_new)
    cost_new = soft_l1_cost(f_new) if np.all(np.isfinite(f_new)) else np.inf
    if not cost_new < cost:
        return None
    done = _small(cost, cost_new, step, x)
    return x_new, f_new, cost_new, done, cost - cost_new <= switch * cost


def _small(cost: float, cost_new: float, step: np.ndarray, x: np.ndarray) -> bool:
    """Whether an accepted step ends the fit: it lowered the cost by at most :data:`FTOL`
    of it, or moved x by at most :data:`XTOL` (relative)."""
    small_f = cost - cost_new <= FTOL * cost
    return small_f or float(np.linalg.norm(step)) <= XTOL * (float(np.linalg.norm(x)) + XTOL)


def _newton_step(
    j: csr_matrix,
    w: np.ndarray,
    f: np.ndarray,
    normal: _Normal | None,
    second: csc_matrix,
    g: np.ndarray,
) -> tuple[np.ndarray, float] | None:
    """Newton's step on the cost, undamped, and the decrease its quadratic model predicts
    (``½ gᵀH⁻¹g``): ``H = JᵀW³J + Σ_k ρ′_k f_k ∇²f_k`` is the cost's exact Hessian
    (``W³ = diag((1 + f²)^(−3/2))``, the soft-L1 loss's ``ρ′ + 2ρ″f²``), ``second`` its
    last sum. None when SuperLU finds it singular."""
    h3, _, _ = normal_equations(j, w * w * w, f, normal)
    full = (h3 + second).tocsc()
    full.sort_indices()
    try:
        step = -splu(full).solve(g)
    except RuntimeError:
        return None
    return step, -0.5 * float(np.sum(g * step))
