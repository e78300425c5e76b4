"""Is one robot's sensor biased? A generalised likelihood-ratio test per robot
(docs/design.md §9; the check the papers leave out: NAO paper 4.1.2 trusts every record,
and its distances come from the D-base of eq. 6, which a miscalibrated robot gets wrong
for every sighting alike).

A robot with a broken distance (a D-base scaled by s) or a displaced camera (every
sighting shifted by b in its own frame) makes *all* its sightings wrong the same way:

    v_rj = s · R(−ψ_r)(p_j − p_r) + b + e_rj.

A sound robot has s = 1, b = 0. The counting test of :mod:`fault_test` (how many of r's
pairs fail their χ² test) needs several pairs each tens of σ off; a bias of 0.3 m over
four sightings is plain as one pattern long before that. So, per robot r, with every
other robot held at its fitted pose:

* **H0** (sound): r's pose (x, y, ψ) fitted to r's own sightings and to the others'
  sightings of r;
* **H1** (biased): r's pose and its bias (s, b_x, b_y) fitted to the same sightings;
* each sighting's misfit split along and across its line of sight and whitened by the
  measured σ_r(d), σ_t(d) (:class:`~agent.core.perception.sighting_noise.SightingNoise`),
  under the robust Cauchy loss (the sightings' tail is heavier than a Gaussian's: a
  wrong pairing must not look like a bias);
* the statistic ``Λ = 2 (cost_H0 − cost_H1)`` has three degrees of freedom more under H1;
  its null distribution is *measured* on fault-free rendered fleets (``python -m
  tools.fit_noise``): Λ / ``bias_scale`` is χ²₃ in its tail, so the p-value is
  ``χ²₃.sf(Λ / bias_scale)``.

A bias is a pattern of *all* r's sightings, so it must show without any one of them:
the statistic is taken with the sighting that fits worst under H0 (r's own or another's
of r) set aside. One gross error (a NAO half hidden at close range, a wrong pairing)
is a rejected sighting, counted by the position test of :mod:`fault_test` at its
measured rate, and never a bias on its own: the Cauchy loss above only slows such a
sighting's growth, and H1's three parameters can still absorb much of it when r has
few sightings (measured: one sighting 13 σ off at 0.7 m among three gives Λ 37, enough
to name a sound robot of a four-NAO fleet if it were kept: ``tests/data/runs``). The fitted bias reported is the
rest's: with two sightings left it is exact and says little (a similarity maps any two
points onto any two).

**Every own sighting, identified where it lands.** A bias moves r's sightings off the
robots they saw, so the fleet's pairing is the first thing it spoils: a sighting 40 %
too long pairs with a farther robot, or with none and stays unpaired. So r's own
sightings enter the test unlabelled, the paired ones and the unpaired ones (``loose``)
alike, and each is matched, under each hypothesis and at every step of its fit, to the
robot it lands nearest to in σ (the max-mixture of Olson & Agarwal, docs/papers.md:
the misfit is the smallest over the robots it could have seen). Under H1 the scaled
sightings land on the robots they saw, under H0 on none, and Λ measures it. The others'
sightings of r keep their pairing: they are sound. ``elsewhere``: more places where a
robot stands that the frame leaves out (a robot left out by the fault test is still
where the others saw it, and r's sightings of it land there). The null scale is
measured on this very statistic (``python -m tools.fit_noise``).

Only r's own sightings carry the bias, so the test needs others who see r (they pin its
position) and at least two sightings of r's own, after the worst is set aside; with
fewer it has no power and returns p = 1. Deterministic: measurements in canonical
(owner, target) order, unpaired sightings in record order, a fixed start, the first of
equally bad sightings set aside and the lowest-indexed of equally near robots matched.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.special import chdtrc

from agent.core.formation.frame.poses import PoseFrame, PoseMeasurement
from agent.core.perception.sighting_noise import SightingNoise

#: The Cauchy loss's scale, in σ: a misfit of a few σ counts as a Gaussian's would, a
#: gross one (a wrong pairing) only logarithmically.
LOSS_SCALE = 3.0
#: Fewest own sightings for the test to have power (3 bias parameters, 2 numbers each).
MIN_OWN = 2
#: Fewest sightings of r by others (they pin r's position apart from its own sightings).
MIN_SEEN = 1


@dataclass(frozen=True)
class BiasFit:
    """One robot's bias test: the statistic, the fitted bias, and the p-value."""

    robot: int
    own: int  #: its own sightings used
    seen: int  #: the others' sightings of it used
    statistic: float  #: Λ = 2 (cost_H0 − cost_H1)
    scale: float  #: fitted s under H1
    shift: tuple[float, float]  #: fitted b under H1, m, in r's fixed frame
    p: float


def _rot(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s], [s, c]])


def bias_fit(
    poses: PoseFrame,
    robot: int,
    noise: SightingNoise,
    bias_scale: float,
    loose: np.ndarray | None = None,
    elsewhere: np.ndarray | None = None,
) -> BiasFit:
    """The test of the module docstring for ``robot`` of ``poses``: H0 fitted on all its
    sightings to find the one that fits worst, then H0 and H1 on the rest. ``loose``
    (k, 2): its own sightings no measurement of ``poses`` uses, in its fixed frame;
    ``elsewhere`` (k, 2): more places, common frame, where they may land.

    Raises
    ------
    ValueError
        ``robot`` not in ``poses``, or ``bias_scale`` not positive.
    """
    if robot not in poses.ids:
        raise ValueError(f"robot {robot} has no pose")
    if not bias_scale > 0.0:
        raise ValueError(f"bias_scale must be > 0, got {bias_scale}")
    # r's own and the others' of r, filtered, then sorted (stably): as the sorted list filtered
    mine = (m for m in poses.measurements if robot in (m.owner, m.target))
    ms = sorted(mine, key=lambda m: (m.owner, m.target))
    own: list[PoseMeasurement | np.ndarray] = [
        m for m in ms if m.owner == robot and m.target != robot
    ]
    if loose is not None:
        own += [np.asarray(v, dtype=np.float64) for v in np.asarray(loose).reshape(-1, 2)]
    seen = [m for m in ms if m.target == robot and m.owner != robot]
    if len(own) < MIN_OWN or len(seen) < MIN_SEEN or len(poses.ids) < 2:
        return BiasFit(robot, len(own), len(seen), 0.0, 1.0, (0.0, 0.0), 1.0)
    x_h0, worst = _Sightings(poses, robot, own, seen, noise, elsewhere).worst()
    n_own = len(own)  # the worst is indexed over own sightings, then the others'
    own = [m for k, m in enumerate(own) if k != worst]
    seen = [m for k, m in enumerate(seen) if k != worst - n_own]
    if len(own) < MIN_OWN or len(seen) < MIN_SEEN:
        return BiasFit(robot, len(own), len(seen), 0.0, 1.0, (0.0, 0.0), 1.0)
    kept = _Sightings(poses, robot, own, seen, noise, elsewhere).fit(x_h0)
    p = float(chdtrc(3, kept.statistic / bias_scale))
    return BiasFit(robot, len(own), len(seen), kept.statistic, kept.scale, kept.shift, p)


@dataclass(frozen=True)
class _Fit:
    """H1 against H0 on one set of sightings."""

    statistic: float  #: Λ = 2 (cost_H0 − cost_H1)
    scale: float  #: fitted s under H1
    shift: tuple[float, float]  #: fitted b under H1


class _Sightings:
    """Robot r's own sightings and the others' sightings of r, whitened by the measured
    noise, with every other robot held at its fitted pose."""

    def __init__(
        self,
        poses: PoseFrame,
        robot: int,
        own: list[PoseMeasurement | np.ndarray],
        seen: list[PoseMeasurement],
        noise: SightingNoise,
        elsewhere: np.ndarray | None = None,
    ) -> None:
        index = {rid: k for k, rid in enumerate(poses.ids)}
        paired = [m for m in own if isinstance(m, PoseMeasurement)]
        loose = [np.asarray(v, dtype=np.float64) for v in own if not isinstance(v, PoseMeasurement)]
        self.n_own, self.n_paired = len(own), len(paired)
        self.x0 = np.array([*poses.positions[index[robot]], poses.headings[index[robot]]])
        v_own = np.array([m.vector for m in paired] + loose, dtype=np.float64).reshape(-1, 2)
        #: where an own sighting may land: every other robot, and ``elsewhere``
        others = [rid for rid in poses.ids if rid != robot]
        self.p_any = poses.positions[[index[rid] for rid in others]]
        #: the robots the fit paired r's sightings with (rows of ``p_any``)
        self.paired_to = np.array([others.index(m.target) for m in paired], dtype=np.intp)
        self.p_tgt = self.p_any[self.paired_to].reshape(-1, 2)
        if elsewhere is not None:
            extra = np.asarray(elsewhere, dtype=np.float64).reshape(-1, 2)
            self.p_any = np.vstack([self.p_any, extra])
        #: True: every own sighting matched where it lands; False: the paired ones keep
        #: their pairing (the first start), the loose ones matched
        self.free = True
        v_seen = np.array([m.vector for m in seen], dtype=np.float64).reshape(-1, 2)
        o = [index[m.owner] for m in seen]
        self.p_obs = poses.positions[o]
        psi_obs = poses.headings[o]
        # whitening: along/across each observed vector, at its own measured distance
        self.v_all = np.vstack([v_own, v_seen])
        d_all = np.hypot(self.v_all[:, 0], self.v_all[:, 1])
        self.u_all = self.v_all / np.maximum(d_all, 1e-9)[:, None]
        self.s_r, self.s_t = noise.sigma_radial(d_all), noise.sigma_tangential(d_all)
        # the others' sightings of r, as seen from each owner: R(−ψ_o)(p_r − p_o)
        self.rot_obs = np.stack([np.array([[c, s], [-s, c]]) for c, s in
                                 zip(np.cos(psi_obs), np.sin(psi_obs), strict=True)])  # fmt: skip
        # the own sightings' columns, for :meth:`_matched`
        n_own = self.n_own
        self.vx, self.vy = self.v_all[:n_own, 0].copy(), self.v_all[:n_own, 1].copy()
        self.ux, self.uy = self.u_all[:n_own, 0].copy(), self.u_all[:n_own, 1].copy()
        self.sr_own, self.st_own = self.s_r[:n_own].copy(), self.s_t[:n_own].copy()
        self._last: tuple[tuple[int, bytes], np.ndarray] | None = None
        # the same numbers by columns, for :meth:`residuals` and :meth:`jacobian` (each
        # product and sum as :meth:`errors` and :meth:`whiten` take it: the same bits)
        self.c_obs, self.s_obs = self.rot_obs[:, 0, 0].copy(), self.rot_obs[:, 0, 1].copy()
        self.ms_obs = self.rot_obs[:, 1, 0].copy()  # −sin ψ_o
        self.px_obs, self.py_obs = self.p_obs[:, 0].copy(), self.p_obs[:, 1].copy()
        self.vx_all, self.vy_all = self.v_all[:, 0].copy(), self.v_all[:, 1].copy()
        self.ux_all, self.uy_all = self.u_all[:, 0].copy(), self.u_all[:, 1].copy()
        self.pax, self.pay = self.p_any[:, 0].copy(), self.p_any[:, 1].copy()
        #: (x's bytes, free) -> the own sightings' (p_target − p_r) at x, for the Jacobian
        self._rel: tuple[tuple[bytes, bool], np.ndarray, np.ndarray] | None = None
        self._seen_jac: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def errors(self, x: np.ndarray, jac_too: bool) -> tuple[np.ndarray, np.ndarray | None]:
        """Misfits (k, 2) and their Jacobian (k, 2, len(x)), owner's frame."""
        n_own = self.n_own
        pr, psi = x[:2], float(x[2])
        scale, shift = (float(x[3]), x[4:6]) if len(x) > 3 else (1.0, np.zeros(2))
        c, s = math.cos(psi), math.sin(psi)
        first = 0 if self.free else self.n_paired
        rel = np.vstack([self.p_tgt[:first], self._landing(first, pr, c, s, scale, shift)]) - pr
        unscaled = np.stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]], 1)
        pred_seen = np.einsum("kij,kj->ki", self.rot_obs, pr[None, :] - self.p_obs)
        e = np.vstack([unscaled * scale + shift, pred_seen]) - self.v_all
        if not jac_too:
            return e, None
        jac = np.zeros((len(e), 2, len(x)))
        jac[:n_own, :, :2] = -scale * np.array([[c, s], [-s, c]])
        jac[:n_own, 0, 2] = scale * (-s * rel[:, 0] + c * rel[:, 1])
        jac[:n_own, 1, 2] = scale * (-c * rel[:, 0] - s * rel[:, 1])
        jac[n_own:, :, :2] = self.rot_obs
        if len(x) > 3:
            jac[:n_own, :, 3] = unscaled
            jac[:n_own, 0, 4] = 1.0
            jac[:n_own, 1, 5] = 1.0
        return e, jac

    def _landing(
        self, first: int, pr: np.ndarray, c: float, s: float, scale: float, shift: np.ndarray
    ) -> np.ndarray:
        """Where each own sighting from ``first`` on lands: the place of the robot it lands
        nearest to (in σ) under the pose and bias, the max-mixture association, redone at
        every evaluation (tie: the first robot)."""
        return np.asarray(self.p_any[self._matched(first, pr, c, s, scale, shift)])

    def _matched(
        self, first: int, pr: np.ndarray, c: float, s: float, scale: float, shift: np.ndarray
    ) -> np.ndarray:
        """The rows of ``p_any`` that the own sightings from ``first`` on land nearest to.
        A pure function of its arguments: the last answer is kept, since the fit asks for
        the Jacobian at the point whose residuals it has just taken."""
        if first == self.n_own:
            return np.zeros(0, dtype=np.intp)
        key = (first, np.array([pr[0], pr[1], c, s, scale, shift[0], shift[1]]).tobytes())
        if self._last is not None and self._last[0] == key:
            return self._last[1]
        relx, rely = self.p_any[:, 0] - pr[0], self.p_any[:, 1] - pr[1]
        px = (c * relx + s * rely) * scale + shift[0]
        py = (-s * relx + c * rely) * scale + shift[1]
        ex = px[None, :] - self.vx[first:, None]  # (sightings, robots)
        ey = py[None, :] - self.vy[first:, None]
        ux, uy = self.ux[first:, None], self.uy[first:, None]
        along = (ex * ux + ey * uy) / self.sr_own[first:, None]
        across = (ey * ux - ex * uy) / self.st_own[first:, None]
        hit = np.asarray((along**2 + across**2).round(9).argmin(axis=1), dtype=np.intp)
        self._last = (key, hit)
        return hit

    def _keeps_pairing(self, x: np.ndarray) -> bool:
        """Whether every paired sighting lands, at ``x``, on the robot the fit paired it
        with (the loose ones are matched alike under both starts)."""
        scale, shift = (float(x[3]), x[4:6]) if len(x) > 3 else (1.0, np.zeros(2))
        psi = float(x[2])
        hit = self._matched(0, x[:2], math.cos(psi), math.sin(psi), scale, shift)[: self.n_paired]
        return bool(np.array_equal(hit, self.paired_to))

    def _best(self, start: np.ndarray) -> tuple[np.ndarray, float]:
        """One hypothesis, every sighting matched where it lands, fitted from ``start``;
        and, unless that solution keeps the fit's pairing, from a second start as well:
        the solution with the fit's pairing kept (the loose sightings matched). The lower
        cost wins (tie: the first). The matched cost is never above the paired one at the
        same x, so the second start is a start of the same problem, not another model; it
        is needed when the pairing holds the pose in a basin the matching alone leaves."""
        self.free = True
        x_a, c_a = _cauchy_fit(self.residuals, self.jacobian, start)
        if self._keeps_pairing(x_a):
            return x_a, c_a
        self.free = False
        x_p, _ = _cauchy_fit(self.residuals, self.jacobian, start)
        self.free = True
        x_b, c_b = _cauchy_fit(self.residuals, self.jacobian, x_p)
        return (x_a, c_a) if c_a <= c_b else (x_b, c_b)

    def whiten(self, e: np.ndarray) -> np.ndarray:
        """(k, 2, ...) misfits (or their derivatives) -> (2k, ...): along, then across
        each line of sight, in σ."""
        shape = (-1,) + (1,) * (e.ndim - 2)
        ux, uy = self.u_all[:, 0].reshape(shape), self.u_all[:, 1].reshape(shape)
        along = (e[:, 0] * ux + e[:, 1] * uy) / self.s_r.reshape(shape)
        across = (e[:, 1] * ux - e[:, 0] * uy) / self.s_t.reshape(shape)
        return np.concatenate([along, across])

    def _targets_rel(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The places the own sightings land on at ``x`` less r's position, by columns
        (as :meth:`errors`' ``rel``; kept for the Jacobian at the same point)."""
        key = (x.tobytes(), self.free)
        if self._rel is not None and self._rel[0] == key:
            return self._rel[1], self._rel[2]
        scale, shift = (float(x[3]), x[4:6]) if len(x) > 3 else (1.0, np.zeros(2))
        psi = float(x[2])
        c, s = math.cos(psi), math.sin(psi)
        first = 0 if self.free else self.n_paired
        rows = self._matched(first, x[:2], c, s, scale, shift)
        if first:
            rows = np.concatenate([self.paired_to[:first], rows])
        relx, rely = self.pax[rows] - x[0], self.pay[rows] - x[1]
        self._rel = (key, relx, rely)
        return relx, rely

    def residuals(self, x: np.ndarray) -> np.ndarray:
        """``whiten(errors(x)[0])``, bit for bit, by columns (no (k, 2) arrays)."""
        relx, rely = self._targets_rel(x)
        psi = float(x[2])
        c, s = math.cos(psi), math.sin(psi)
        ox, oy = c * relx + s * rely, -s * relx + c * rely
        if len(x) > 3:
            scale = float(x[3])
            ox, oy = ox * scale + x[4], oy * scale + x[5]
        else:
            ox, oy = ox * 1.0 + 0.0, oy * 1.0 + 0.0
        dx, dy = x[0] - self.px_obs, x[1] - self.py_obs
        ex = np.concatenate([ox, self.c_obs * dx + self.s_obs * dy]) - self.vx_all
        ey = np.concatenate([oy, self.ms_obs * dx + self.c_obs * dy]) - self.vy_all
        along = (ex * self.ux_all + ey * self.uy_all) / self.s_r
        across = (ey * self.ux_all - ex * self.uy_all) / self.s_t
        return np.concatenate([along, across])

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """``whiten(errors(x, True)[1])``, bit for bit, by columns."""
        relx, rely = self._targets_rel(x)
        n_own, k, nx = self.n_own, len(self.v_all), len(x)
        psi = float(x[2])
        c, s = math.cos(psi), math.sin(psi)
        scale = float(x[3]) if nx > 3 else 1.0
        j0 = np.zeros((n_own, nx))  # d(misfit along x) / dx, as ``errors`` fills jac[:, 0]
        j1 = np.zeros((n_own, nx))  # d(misfit along y) / dx
        m = -scale * np.array([[c, s], [-s, c]])
        j0[:, 0], j0[:, 1] = m[0, 0], m[0, 1]
        j1[:, 0], j1[:, 1] = m[1, 0], m[1, 1]
        j0[:, 2] = scale * (-s * relx + c * rely)
        j1[:, 2] = scale * (-c * relx - s * rely)
        if nx > 3:
            j0[:, 3] = c * relx + s * rely
            j1[:, 3] = -s * relx + c * rely
            j0[:, 4] = 1.0
            j1[:, 5] = 1.0
        ux, uy = self.ux_all[:n_own, None], self.uy_all[:n_own, None]
        out = np.empty((2 * k, nx))
        out[:n_own] = (j0 * ux + j1 * uy) / self.s_r[:n_own, None]
        out[k : k + n_own] = (j1 * ux - j0 * uy) / self.s_t[:n_own, None]
        seen_along, seen_across = self._seen_jacobian(nx)
        out[n_own:k], out[k + n_own :] = seen_along, seen_across
        return out

    def _seen_jacobian(self, nx: int) -> tuple[np.ndarray, np.ndarray]:
        """The whitened Jacobian of the others' sightings of r (along, across), the same
        at every x: they move with r's position only, by their owners' fixed headings."""
        if nx not in self._seen_jac:
            n_own, k = self.n_own, len(self.v_all)
            j0, j1 = np.zeros((k - n_own, nx)), np.zeros((k - n_own, nx))
            j0[:, 0], j0[:, 1] = self.c_obs, self.s_obs
            j1[:, 0], j1[:, 1] = self.ms_obs, self.c_obs
            ux, uy = self.ux_all[n_own:, None], self.uy_all[n_own:, None]
            along = (j0 * ux + j1 * uy) / self.s_r[n_own:, None]
            across = (j1 * ux - j0 * uy) / self.s_t[n_own:, None]
            self._seen_jac[nx] = (along, across)
        return self._seen_jac[nx]

    def worst(self) -> tuple[np.ndarray, int]:
        """H0's solution and the sighting (own, then seen) that fits worst under it (by its
        whitened χ², the first of equal ones)."""
        x_h0, _ = self._best(self.x0)
        r, k = self.residuals(x_h0), len(self.v_all)
        return x_h0, int(np.argmax(np.round(r[:k] ** 2 + r[k:] ** 2, 9)))

    def fit(self, start: np.ndarray) -> _Fit:
        """H0 from ``start`` (r's pose), H1 from H0's solution with no bias, and Λ."""
        x_h0, cost0 = self._best(start)
        x_h1, cost1 = self._best(np.concatenate([x_h0, [1.0, 0.0, 0.0]]))
        return _Fit(max(0.0, 2.0 * (cost0 - cost1)), float(x_h1[3]),
                    (float(x_h1[4]), float(x_h1[5])))  # fmt: skip


#: Gauss-Newton iterations of :func:`_cauchy_fit` at most, and its relative stop.
MAX_ITER = 30
TOL = 1e-7


def cauchy_cost(r: np.ndarray) -> float:
    """½ Σ f² log(1 + (r/f)²), f = :data:`LOSS_SCALE` (scipy's ``loss="cauchy"``)."""
    f2 = LOSS_SCALE * LOSS_SCALE
    return float(0.5 * f2 * np.log1p(r * r / f2).sum())


def _cauchy_fit(
    residuals: Callable[[np.ndarray], np.ndarray],
    jacobian: Callable[[np.ndarray], np.ndarray],
    x0: np.ndarray,
) -> tuple[np.ndarray, float]:
    """Minimise :func:`cauchy_cost` of ``residuals`` from ``x0`` by iteratively reweighted
    Gauss-Newton (weights ``1 / (1 + (r/f)²)``), halving a step that does not lower the
    cost; returns (x, cost). A few small dense solves: a robot has tens of sightings."""
    x = np.asarray(x0, dtype=np.float64).copy()
    r = residuals(x)
    cost = cauchy_cost(r)
    f2 = LOSS_SCALE * LOSS_SCALE
    ridge = 1e-9 * np.eye(len(x))
    for _ in range(MAX_ITER):
        j = jacobian(x)
        w = 1.0 / (1.0 + r * r / f2)
        jw = j * w[:, None]
        try:
            step = np.linalg.solve(jw.T @ j + ridge, -(jw.T @ r))
        except np.linalg.LinAlgError:
            break
        for _ in range(20):
            trial = x + step
            r_trial = residuals(trial)
            c_trial = cauchy_cost(r_trial)
            if c_trial <= cost:
                break
            step = step / 2.0
        else:
            break
        done = cost - c_trial <= TOL * max(cost, 1.0)
        x, r, cost = trial, r_trial, c_trial
        if done:
            break
    return x, cost
