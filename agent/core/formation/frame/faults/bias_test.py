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

**Every robot at once** (:func:`bias_fits`, what the fault test runs): the robots' fits
are independent (each holds the others at their fitted poses), so they run side by side,
one array operation for every robot still fitting at each Gauss-Newton step
(:class:`_Batch`): fitted one at a time, the robots of a 50-NAO fleet cost mostly
numpy's overhead per call on arrays of tens of numbers. Each robot's misfits and Jacobian are its own, element for
element; only the sums over its sightings run over padded rows, so its Λ is its fit
alone's up to rounding (``tests/formation/frame/faults/test_bias_batch.py``).

Only r's own sightings carry the bias, so the test needs others who see r (they pin its
position) and at least two sightings of r's own, after the worst is set aside; with
fewer it has no power and returns p = 1. Deterministic: measurements in canonical
(owner, target) order, unpaired sightings in record order, a fixed start, the first of
equally bad sightings set aside and the lowest-indexed of equally near robots matched.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
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
    return bias_fits(poses, (robot,), noise, bias_scale, {robot: loose}, elsewhere)[robot]


def bias_fits(
    poses: PoseFrame,
    robots: Sequence[int],
    noise: SightingNoise,
    bias_scale: float,
    loose: Mapping[int, np.ndarray | None] | None = None,
    elsewhere: np.ndarray | None = None,
) -> dict[int, BiasFit]:
    """:func:`bias_fit` of each of ``robots`` (``loose``: each one's own sightings no
    measurement uses, as :func:`bias_fit`'s), their fits run side by side (one array
    operation for all the robots at each step: :class:`_Batch`); each robot's answer is
    its own fit's, whatever others are fitted beside it, up to rounding.

    Raises
    ------
    ValueError
        A robot not in ``poses``, or ``bias_scale`` not positive.
    """
    for robot in robots:
        if robot not in poses.ids:
            raise ValueError(f"robot {robot} has no pose")
    if not bias_scale > 0.0:
        raise ValueError(f"bias_scale must be > 0, got {bias_scale}")
    loose = {} if loose is None else loose
    out: dict[int, BiasFit] = {}
    tried: list[tuple[int, list[PoseMeasurement | np.ndarray], list[PoseMeasurement]]] = []
    # each robot's measurements (its own and the others' of it), in their order
    of: dict[int, list[PoseMeasurement]] = {robot: [] for robot in robots}
    for m in poses.measurements:
        for robot in (m.owner, m.target) if m.owner != m.target else (m.owner,):
            if robot in of:
                of[robot].append(m)
    for robot in robots:
        # r's own and the others' of r, filtered, then sorted (stably): as the sorted
        # list filtered
        ms = sorted(of[robot], key=lambda m: (m.owner, m.target))
        own: list[PoseMeasurement | np.ndarray] = [
            m for m in ms if m.owner == robot and m.target != robot
        ]
        extra = loose.get(robot)
        if extra is not None:
            own += [np.asarray(v, dtype=np.float64) for v in np.asarray(extra).reshape(-1, 2)]
        seen = [m for m in ms if m.target == robot and m.owner != robot]
        if len(own) < MIN_OWN or len(seen) < MIN_SEEN or len(poses.ids) < 2:
            out[robot] = BiasFit(robot, len(own), len(seen), 0.0, 1.0, (0.0, 0.0), 1.0)
        else:
            tried.append((robot, own, seen))
    if not tried:
        return out
    every = [_Sightings(poses, r, own, seen, noise, elsewhere) for r, own, seen in tried]
    x_all, worst = _Batch(every).worst()
    rest: list[tuple[int, list[PoseMeasurement | np.ndarray], list[PoseMeasurement]]] = []
    starts = []
    for (robot, own, seen), x_h0, w in zip(tried, x_all, worst, strict=True):
        n_own = len(own)  # the worst is indexed over own sightings, then the others'
        own = [m for k, m in enumerate(own) if k != w]
        seen = [m for k, m in enumerate(seen) if k != w - n_own]
        if len(own) < MIN_OWN or len(seen) < MIN_SEEN:
            out[robot] = BiasFit(robot, len(own), len(seen), 0.0, 1.0, (0.0, 0.0), 1.0)
        else:
            rest.append((robot, own, seen))
            starts.append(x_h0)
    if rest:
        kept = [_Sightings(poses, r, own, seen, noise, elsewhere) for r, own, seen in rest]
        for (robot, own, seen), fit in zip(rest, _Batch(kept).fit(np.array(starts)), strict=True):
            p = float(chdtrc(3, fit.statistic / bias_scale))
            out[robot] = BiasFit(robot, len(own), len(seen), fit.statistic, fit.scale, fit.shift, p)
    return {r: out[r] for r in robots}


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
        cos_obs, sin_obs = np.cos(psi_obs), np.sin(psi_obs)
        self.rot_obs = np.empty((len(o), 2, 2))
        self.rot_obs[:, 0, 0], self.rot_obs[:, 0, 1] = cos_obs, sin_obs
        self.rot_obs[:, 1, 0], self.rot_obs[:, 1, 1] = -sin_obs, cos_obs
        # the own sightings' columns, for :meth:`_matched`
        n_own = self.n_own
        self.vx, self.vy = self.v_all[:n_own, 0].copy(), self.v_all[:n_own, 1].copy()
        self.ux, self.uy = self.u_all[:n_own, 0].copy(), self.u_all[:n_own, 1].copy()
        self.sr_own, self.st_own = self.s_r[:n_own].copy(), self.s_t[:n_own].copy()
        # the same numbers by columns, for :class:`_Batch` (each product and sum as
        # :meth:`errors` and :meth:`whiten` take it: the same bits)
        self.c_obs, self.s_obs = self.rot_obs[:, 0, 0].copy(), self.rot_obs[:, 0, 1].copy()
        self.ms_obs = self.rot_obs[:, 1, 0].copy()  # −sin ψ_o
        self.px_obs, self.py_obs = self.p_obs[:, 0].copy(), self.p_obs[:, 1].copy()
        self.vx_all, self.vy_all = self.v_all[:, 0].copy(), self.v_all[:, 1].copy()
        self.ux_all, self.uy_all = self.u_all[:, 0].copy(), self.u_all[:, 1].copy()
        self.pax, self.pay = self.p_any[:, 0].copy(), self.p_any[:, 1].copy()

    def errors(self, x: np.ndarray, jac_too: bool) -> tuple[np.ndarray, np.ndarray | None]:
        """Misfits (k, 2) and their Jacobian (k, 2, len(x)), owner's frame."""
        n_own = self.n_own
        pr, psi = x[:2], float(x[2])
        scale, shift = (float(x[3]), x[4:6]) if len(x) > 3 else (1.0, np.zeros(2))
        c, s = math.cos(psi), math.sin(psi)
        first = 0 if self.free else self.n_paired
        landing = self.p_any[self._matched(first, pr, c, s, scale, shift)]
        rel = np.vstack([self.p_tgt[:first], landing]) - pr
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

    def _matched(
        self, first: int, pr: np.ndarray, c: float, s: float, scale: float, shift: np.ndarray
    ) -> np.ndarray:
        """The rows of ``p_any`` that the own sightings from ``first`` on land nearest to
        (in σ) under the pose and bias: the max-mixture association, redone at every
        evaluation (tie: the first robot)."""
        relx, rely = self.p_any[:, 0] - pr[0], self.p_any[:, 1] - pr[1]
        px = (c * relx + s * rely) * scale + shift[0]
        py = (-s * relx + c * rely) * scale + shift[1]
        ex = px[None, :] - self.vx[first:, None]  # (sightings, robots)
        ey = py[None, :] - self.vy[first:, None]
        ux, uy = self.ux[first:, None], self.uy[first:, None]
        along = (ex * ux + ey * uy) / self.sr_own[first:, None]
        across = (ey * ux - ex * uy) / self.st_own[first:, None]
        return np.asarray((along**2 + across**2).round(9).argmin(axis=1), dtype=np.intp)

    def whiten(self, e: np.ndarray) -> np.ndarray:
        """(k, 2, ...) misfits (or their derivatives) -> (2k, ...): along, then across
        each line of sight, in σ."""
        shape = (-1,) + (1,) * (e.ndim - 2)
        ux, uy = self.u_all[:, 0].reshape(shape), self.u_all[:, 1].reshape(shape)
        along = (e[:, 0] * ux + e[:, 1] * uy) / self.s_r.reshape(shape)
        across = (e[:, 1] * ux - e[:, 0] * uy) / self.s_t.reshape(shape)
        return np.concatenate([along, across])


#: Gauss-Newton iterations of :meth:`_Batch.cauchy_fit` at most, and its relative stop:
#: every robot's Λ of the 50-NAO runs of ``tests/data/runs/n50_random_s1018.json`` stays
#: within 0.04 of its value at 1e-7 (a robot is rejected from Λ ≈ 23·bias_scale on), for a
#: third less time; on the corpus a faulty robot's Λ of 57-716 moves by up to 31 (its
#: matched sightings stop elsewhere), every verdict the same.
MAX_ITER = 30
TOL = 1e-5
#: Tries of a Gauss-Newton step at most: the full step, then halved, halved again, ...
HALVINGS = 20


def cauchy_cost(r: np.ndarray) -> np.ndarray:
    """½ Σ f² log(1 + (r/f)²) over the last axis, f = :data:`LOSS_SCALE` (scipy's
    ``loss="cauchy"``)."""
    f2 = LOSS_SCALE * LOSS_SCALE
    return np.asarray(0.5 * f2 * np.log1p(r * r / f2).sum(axis=-1))


class _Batch:
    """The fits of several robots' :class:`_Sightings` side by side: each robot a row of
    padded arrays (own sightings, the others' sightings of it, the places its sightings
    may land), each step of each fit one array operation for every robot still fitting.
    A robot's misfits and their Jacobian are :meth:`_Sightings.errors` whitened, element
    for element (the same products and sums in the same order); only the sums over its
    sightings (the cost, the normal equations) run over padded rows, so a robot's fit
    may differ from its fit alone in the last bits."""

    def __init__(self, fits: Sequence[_Sightings]) -> None:
        self.size = len(fits)
        self.ko = ko = max(f.n_own for f in fits)
        self.ks = ks = max(len(f.v_all) - f.n_own for f in fits)
        na = max(len(f.p_any) for f in fits)
        self.n_own = np.array([f.n_own for f in fits])
        self.n_seen = np.array([len(f.v_all) - f.n_own for f in fits])
        self.n_paired = np.array([f.n_paired for f in fits])
        self.x0 = np.array([f.x0 for f in fits])
        # padded sightings: at the origin, unit σ, zero direction (their misfits are set to
        # 0 by the masks); padded places far off (never the nearest)
        self.own_mask = np.arange(ko)[None, :] < self.n_own[:, None]
        self.seen_mask = np.arange(ks)[None, :] < self.n_seen[:, None]
        self.paired = np.arange(ko)[None, :] < self.n_paired[:, None]
        #: (vx, vy, ux, uy, σ_r, σ_t) of each robot's own sightings
        self.own = np.zeros((6, self.size, ko))
        self.own[4:] = 1.0
        #: the same of the others' sightings of it, then each owner's cos ψ, sin ψ, −sin ψ,
        #: x, y, then their whitened Jacobian (along x, along y, across x, across y): they
        #: move with the robot's position only
        self.seen = np.zeros((15, self.size, ks))
        self.seen[4:6] = 1.0
        self.places = np.full((2, self.size, na), 1e12)
        self.paired_to = np.zeros((self.size, ko), dtype=np.intp)
        for k, f in enumerate(fits):
            o, n = f.n_own, len(f.v_all)
            cols = (f.vx_all, f.vy_all, f.ux_all, f.uy_all, f.s_r, f.s_t)
            for c, col in enumerate(cols):
                self.own[c, k, :o] = col[:o]
                self.seen[c, k, : n - o] = col[o:]
            for c, col in enumerate((f.c_obs, f.s_obs, f.ms_obs, f.px_obs, f.py_obs)):
                self.seen[6 + c, k, : n - o] = col
            self.places[0, k, : len(f.pax)], self.places[1, k, : len(f.pay)] = f.pax, f.pay
            self.paired_to[k, : f.n_paired] = f.paired_to
        _, _, sux, suy, ssr, sst, c_obs, s_obs, ms_obs = self.seen[:9]
        self.seen[11] = (c_obs * sux + ms_obs * suy) / ssr
        self.seen[12] = (s_obs * sux + c_obs * suy) / ssr
        self.seen[13] = (ms_obs * sux - c_obs * suy) / sst
        self.seen[14] = (c_obs * sux - s_obs * suy) / sst

    def _landing(self, sel: np.ndarray, x: np.ndarray, free: bool) -> np.ndarray:
        """The rows of the places each own sighting of the robots ``sel`` lands on at
        ``x`` (:meth:`_Sightings._matched`: nearest in σ, tie the first; ``free`` False:
        the paired ones on the robot the fit paired them with)."""
        vx, vy, ux, uy, sr, st = (a[:, :, None] for a in self.own[:, sel])
        pax, pay = self.places[:, sel]
        c, s = _cos_sin(x[:, 2])
        scale, sx, sy = _bias(x)
        relx = pax - x[:, 0:1]
        rely = pay - x[:, 1:2]
        px = ((c * relx + s * rely) * scale + sx)[:, None, :]
        py = ((-s * relx + c * rely) * scale + sy)[:, None, :]
        ex = px - vx  # (robots, sightings, places)
        ey = py - vy
        # along = (ex·ux + ey·uy) / σ_r, across = (ey·ux − ex·uy) / σ_t, in place
        along = ex * ux
        along += ey * uy
        along /= sr
        ey *= ux
        ex *= uy
        ey -= ex
        ey /= st
        np.square(along, out=along)
        np.square(ey, out=ey)
        along += ey
        hit = np.asarray(along.round(9, out=along).argmin(axis=2), dtype=np.intp)
        if not free:
            hit = np.where(self.paired[sel], self.paired_to[sel], hit)
        return hit

    def residuals(
        self, sel: np.ndarray, x: np.ndarray, free: bool
    ) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
        """Whitened misfits of the robots ``sel`` at ``x`` (one row each: along own, along
        seen, across own, across seen; padded entries 0), and where their own sightings
        land less their position (for :meth:`jacobian` at the same point)."""
        rows = self._landing(sel, x, free)
        pax, pay = self.places[:, sel]
        relx = np.take_along_axis(pax, rows, axis=1) - x[:, 0:1]
        rely = np.take_along_axis(pay, rows, axis=1) - x[:, 1:2]
        c, s = _cos_sin(x[:, 2])
        ox, oy = c * relx + s * rely, -s * relx + c * rely
        scale, sx, sy = _bias(x)
        ox, oy = ox * scale + sx, oy * scale + sy
        vx, vy, ux, uy, sr, st = self.own[:, sel]
        ex, ey = ox - vx, oy - vy
        keep = self.own_mask[sel]
        own_al = np.where(keep, (ex * ux + ey * uy) / sr, 0.0)
        own_ac = np.where(keep, (ey * ux - ex * uy) / st, 0.0)
        vx, vy, ux, uy, sr, st, c_obs, s_obs, ms_obs, px_obs, py_obs = self.seen[:11, sel]
        dx, dy = x[:, 0:1] - px_obs, x[:, 1:2] - py_obs
        ex = c_obs * dx + s_obs * dy - vx
        ey = ms_obs * dx + c_obs * dy - vy
        keep = self.seen_mask[sel]
        seen_al = np.where(keep, (ex * ux + ey * uy) / sr, 0.0)
        seen_ac = np.where(keep, (ey * ux - ex * uy) / st, 0.0)
        return np.concatenate([own_al, seen_al, own_ac, seen_ac], axis=1), (relx, rely)

    def jacobian(
        self, sel: np.ndarray, x: np.ndarray, rel: tuple[np.ndarray, np.ndarray]
    ) -> np.ndarray:
        """(robots, rows of :meth:`residuals`, len(x)): the whitened Jacobian at ``x``
        (``rel`` from :meth:`residuals` at the same ``x``), as
        :meth:`_Sightings.errors`' Jacobian whitened."""
        relx, rely = rel
        m, nx = len(sel), x.shape[1]
        c, s = _cos_sin(x[:, 2])
        scale = x[:, 3:4] if nx > 3 else np.ones((m, 1))
        neg = -scale
        j0 = np.zeros((m, self.ko, nx))  # d(misfit along x) / dx, as ``errors`` fills it
        j1 = np.zeros((m, self.ko, nx))  # d(misfit along y) / dx
        j0[:, :, 0], j0[:, :, 1] = neg * c, neg * s
        j1[:, :, 0], j1[:, :, 1] = neg * -s, neg * c
        j0[:, :, 2] = scale * (-s * relx + c * rely)
        j1[:, :, 2] = scale * (-c * relx - s * rely)
        if nx > 3:
            j0[:, :, 3] = c * relx + s * rely
            j1[:, :, 3] = -s * relx + c * rely
            j0[:, :, 4] = 1.0
            j1[:, :, 5] = 1.0
        ux, uy, sr, st = (a[:, :, None] for a in self.own[2:, sel])
        keep = self.own_mask[sel][:, :, None]
        out = np.zeros((m, 2 * (self.ko + self.ks), nx))
        ko, ks = self.ko, self.ks
        out[:, :ko] = np.where(keep, (j0 * ux + j1 * uy) / sr, 0.0)
        out[:, ko + ks : 2 * ko + ks] = np.where(keep, (j1 * ux - j0 * uy) / st, 0.0)
        ax, ay, cx, cy = self.seen[11:, sel]
        keep_s = self.seen_mask[sel]
        out[:, ko : ko + ks, 0] = np.where(keep_s, ax, 0.0)
        out[:, ko : ko + ks, 1] = np.where(keep_s, ay, 0.0)
        out[:, 2 * ko + ks :, 0] = np.where(keep_s, cx, 0.0)
        out[:, 2 * ko + ks :, 1] = np.where(keep_s, cy, 0.0)
        return out

    def cauchy_fit(
        self, sel: np.ndarray, x0: np.ndarray, free: bool
    ) -> tuple[np.ndarray, np.ndarray]:
        """Minimise each robot's :func:`cauchy_cost` from ``x0`` by iteratively reweighted
        Gauss-Newton (weights ``1 / (1 + (r/f)²)``), halving a step that does not lower
        its cost (a robot whose step does not after 20 halvings, or whose normal equations
        are singular, stops; the halvings are tried at once: the first that lowers the
        cost is the one halving after halving finds); returns (x, cost) per robot."""
        x = np.array(x0, dtype=np.float64)
        r, (relx, rely) = self.residuals(sel, x, free)
        cost = np.asarray(cauchy_cost(r))
        f2 = LOSS_SCALE * LOSS_SCALE
        ridge = 1e-9 * np.eye(x.shape[1])
        halves = 0.5 ** np.arange(1, HALVINGS)[None, :, None]
        going = np.arange(len(sel))
        for _ in range(MAX_ITER):
            if going.size == 0:
                break
            j = self.jacobian(sel[going], x[going], (relx[going], rely[going]))
            rg = r[going]
            jw = j * (1.0 / (1.0 + rg * rg / f2))[:, :, None]
            normal = np.einsum("mki,mkj->mij", jw, j) + ridge
            step, ok = _solve(normal, -np.einsum("mki,mk->mi", jw, rg))
            going, step = going[ok], step[ok]
            trial = x[going] + step
            r_t, (rx_t, ry_t) = self.residuals(sel[going], trial, free)
            c_t = np.asarray(cauchy_cost(r_t))
            better = c_t <= cost[going]
            if not better.all():
                # the halved steps of those the full step did not lower, all at once
                who = np.flatnonzero(~better)
                tries = (x[going[who]][:, None, :] + step[who][:, None, :] * halves).reshape(
                    -1, x.shape[1]
                )
                r_h, (rx_h, ry_h) = self.residuals(np.repeat(sel[going[who]], halves.shape[1]),
                                                   tries, free)  # fmt: skip
                c_h = np.asarray(cauchy_cost(r_h)).reshape(len(who), -1)
                lower = c_h <= cost[going[who]][:, None]
                found = lower.any(axis=1)
                pick = who.size and (np.arange(len(who)) * halves.shape[1] + lower.argmax(axis=1))
                pick = np.asarray(pick)[found]
                into = who[found]
                trial[into], r_t[into], c_t[into] = tries[pick], r_h[pick], c_h.reshape(-1)[pick]
                rx_t[into], ry_t[into] = rx_h[pick], ry_h[pick]
                better[into] = True
            going, trial, r_t, c_t = going[better], trial[better], r_t[better], c_t[better]
            done = cost[going] - c_t <= TOL * np.maximum(cost[going], 1.0)
            x[going], r[going], cost[going] = trial, r_t, c_t
            relx[going], rely[going] = rx_t[better], ry_t[better]
            going = going[~done]
        return x, cost

    def _keeps_pairing(self, sel: np.ndarray, x: np.ndarray) -> np.ndarray:
        """Whether every paired sighting of each robot lands, at ``x``, on the robot the
        fit paired it with (the loose ones are matched alike under both starts)."""
        hit = self._landing(sel, x, True)
        return np.asarray(np.all((hit == self.paired_to[sel]) | ~self.paired[sel], axis=1))

    def best(self, start: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One hypothesis for every robot, every sighting matched where it lands, fitted
        from ``start``; and, for a robot whose solution does not keep the fit's pairing,
        from a second start as well: the solution with the fit's pairing kept (the loose
        sightings matched). The lower cost wins (tie: the first). The matched cost is
        never above the paired one at the same x, so the second start is a start of the
        same problem, not another model; it is needed when the pairing holds the pose in
        a basin the matching alone leaves."""
        every = np.arange(self.size)
        x_a, c_a = self.cauchy_fit(every, start, True)
        other = np.flatnonzero(~self._keeps_pairing(every, x_a))
        if other.size:
            x_p, _ = self.cauchy_fit(other, start[other], False)
            x_b, c_b = self.cauchy_fit(other, x_p, True)
            second = c_b < c_a[other]
            x_a[other[second]], c_a[other[second]] = x_b[second], c_b[second]
        return x_a, c_a

    def worst(self) -> tuple[np.ndarray, list[int]]:
        """H0's solution of each robot and the sighting (own, then seen) that fits worst
        under it (by its whitened χ², the first of equal ones)."""
        x_h0, _ = self.best(self.x0)
        r, _ = self.residuals(np.arange(self.size), x_h0, True)
        ko, ks = self.ko, self.ks
        chi = np.round(r[:, : ko + ks] ** 2 + r[:, ko + ks :] ** 2, 9)
        out = []
        for k in range(self.size):
            n_own, n_seen = int(self.n_own[k]), int(self.seen_mask[k].sum())
            row = np.concatenate([chi[k, :n_own], chi[k, ko : ko + n_seen]])
            out.append(int(np.argmax(row)))
        return x_h0, out

    def fit(self, start: np.ndarray) -> list[_Fit]:
        """H0 from ``start`` (each robot's pose), H1 from H0's solution with no bias, and
        Λ, for every robot."""
        x_h0, cost0 = self.best(start)
        no_bias = np.tile([1.0, 0.0, 0.0], (self.size, 1))
        x_h1, cost1 = self.best(np.concatenate([x_h0, no_bias], axis=1))
        return [_Fit(max(0.0, 2.0 * float(c0 - c1)), float(x1[3]), (float(x1[4]), float(x1[5])))
                for c0, c1, x1 in zip(cost0, cost1, x_h1, strict=True)]  # fmt: skip


def _cos_sin(psi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """cos ψ and sin ψ of each robot as columns, by ``math`` (the floats of
    :meth:`_Sightings.errors`)."""
    values = np.asarray(psi, dtype=np.float64).tolist()
    c = np.fromiter(map(math.cos, values), dtype=np.float64, count=len(values))[:, None]
    s = np.fromiter(map(math.sin, values), dtype=np.float64, count=len(values))[:, None]
    return c, s


def _bias(x: np.ndarray) -> tuple[np.ndarray | float, np.ndarray | float, np.ndarray | float]:
    """(s, b_x, b_y) of each robot as columns: those of ``x`` under H1, none under H0."""
    if x.shape[1] > 3:
        return x[:, 3:4], x[:, 4:5], x[:, 5:6]
    return 1.0, 0.0, 0.0


def _solve(normal: np.ndarray, grad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each robot's Gauss-Newton step, and whether its normal equations could be solved
    (a singular robot stops, the others go on)."""
    try:
        return np.linalg.solve(normal, grad[:, :, None])[:, :, 0], np.ones(len(grad), dtype=bool)
    except np.linalg.LinAlgError:
        step, ok = np.zeros_like(grad), np.ones(len(grad), dtype=bool)
        for k in range(len(grad)):
            try:
                step[k] = np.linalg.solve(normal[k], grad[k])
            except np.linalg.LinAlgError:
                ok[k] = False
        return step, ok
