"""``python -m tools.fit_noise [--corpus DIR]``: fit the sighting noise model
(:mod:`agent.core.perception.sighting_noise`) on the corpus of rendered records
(``python -m tools.corpus``), and draw it.

Only the fleets without a fault and not held out (:func:`tools.corpus.held_out`) are
used.

* Masks: each sighting is placed in the world through its owner's *true* start pose (a
  robot's fixed frame is its start pose, facing +y) and matched to the nearest other
  robot (within ``GATE0 + GATE1·d``); the mask errors (modulo π) of the matched ones give
  ``σ_m`` (robust, of those within 20° of 0), ``w0`` (share within 3σ_m of 0) and
  ``w90`` (share within 3σ_m of ±90°); of the masks turned back to their target's
  start heading (records with times), ``w180`` is the share whose error modulo 2π is
  beyond ±90° (the NAO read the other way round; a corpus without times keeps the
  shipped figure); ``w180_view`` the same share by the bin of |θ| as the camera read
  it (:func:`reversal_by_view`).
* Each fleet is fitted as the agents' general candidate fits it
  (:func:`agent.core.formation.frame.poses.fit_from_graph`), and only the fits that are
  right (every start within 0.15 m and 10° of the truth) are kept: the test's null model
  is that of a correct frame. Their residuals, along and across each sighting's line of
  sight, are binned by distance; each bin's σ is the one of a Gaussian with the same
  median |residual| (robust: the gross errors are what ``p_reject`` counts);
  ``σ(d)² = a² + (b·d²)²`` is fitted to them in relative terms (least squares on log σ,
  weighted by the bin's count): ``σ_r(d)``, ``σ_t(d)``.
* The χ² test of :mod:`agent.core.formation.frame.faults.fault_test` is run on those fits with
  that σ: the share of their pairs rejected, binned by distance and fitted by a line in
  d, is ``p_reject``; lost strays per sighting, ``p_stray`` (no fault was injected, so
  every rejection is a false one).
* ``a0``, the rate of a sound robot's sightings lost when it is tested alone against the
  others at their fitted poses (:func:`alone_losses`, the test of
  :func:`agent.core.formation.frame.faults.alone.alone_test`), counted conservatively as
  ``(k + 1) / (n + 2)``;
* ``bias_scale``, the bias test's null scale (:func:`bias_scale`: its statistic over sound
  robots against χ²₃, at the 90th and 99th percentiles);
* ``mask_scale``, the heading test's null scale (:func:`null_scale`: Wilks' statistic
  over the sound robots whose records carry times, against χ²₁ at the 90th and 99th
  percentiles, never below 1);
* ``rho``, the rate of sound robots seen turned as a whole beyond that: of the sound
  robots with times (masks turned back to their start heading), those failing the
  scaled test at ``TURNED_P`` beyond the share the model itself puts there
  (:func:`excess_rate`: 0 unless their count is significantly above it); ``rho_untimed``
  the share over robots whose records carry no times (masks as recorded), counted
  conservatively as ``(k + 1) / (n + 1)``. A corpus without robots of one kind keeps the shipped figures of
  that kind.

Prints the model with its figures, writes it (``--write``: into the shipped data folder)
and draws ``--png``.
"""

from __future__ import annotations

import argparse
import itertools
import math
import sys
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import chi2

from agent.adapters import FormationAdapter
from agent.core.formation.frame.poses import PoseFrame
from agent.core.formation.frame.records import mask_orientation, mask_view
from agent.core.perception.sighting_noise import (
    VIEW_BINS,
    SightingNoise,
    shipped_noise,
    split,
    view_bin,
)
from agent.wire import NeighborRecordMsg
from tools.corpus import Run, held_out, load_corpus
from tools.lib.frame_fit import frame_error

GATE0, GATE1 = 0.3, 0.2  #: a sighting is matched when within GATE0 + GATE1·d of a robot
#: A fit is a correct frame, whose residuals the null model describes, within these
#: (the frame accuracy the fleet is judged by: docs/results.md)
FRAME_POS, FRAME_PSI = 0.15, math.radians(10.0)
TURNED_P = 1e-3  #: a sound robot's masks agree on an offset: Wilks' p below this
BINS = np.array([0.0, 0.75, 1.0, 1.25, 1.5, 2.0, 2.5, 3.5])


@dataclass(frozen=True)
class Matched:
    """Every sighting of a set of runs against the truth."""

    distance: np.ndarray  # true distance of the matched robot (nan: not matched)
    measured: np.ndarray  # |v|
    radial: np.ndarray  # |v| - d
    tangential: np.ndarray  # d · bearing error
    mask: np.ndarray  # mask error modulo π (nan: no mask)
    #: 1 where a mask turned back by the records' times reads its target the other way
    #: round (error modulo 2π beyond ±90°), 0 where not (nan: no such mask)
    flip: np.ndarray
    #: the mask's θ as the camera read it, before the turn-back (nan: no mask)
    view: np.ndarray


def _wrap(a: np.ndarray) -> np.ndarray:
    return np.asarray((a + math.pi) % (2 * math.pi) - math.pi)


def _wrap_half(a: np.ndarray) -> np.ndarray:
    return np.asarray((a + math.pi / 2) % math.pi - math.pi / 2)


def match(runs: list[Run]) -> Matched:
    """Match every sighting of ``runs`` to the truth (module docstring)."""
    cols: list[list[float]] = [[], [], [], [], [], [], []]
    for run in runs:
        ids = sorted(run.truth)
        pos = np.array([run.truth[i][:2] for i in ids])
        core = {r.robot_id: r for r in FormationAdapter.records(run.records)}
        for rec in run.records:
            if rec.sender not in run.truth or not rec.neighbours:
                continue
            x, y, h = run.truth[rec.sender]
            v = np.array(rec.neighbours, dtype=np.float64).reshape(-1, 2)
            c, s = math.cos(h - math.pi / 2), math.sin(h - math.pi / 2)
            world = np.array([x, y]) + v @ np.array([[c, s], [-s, c]])
            others = [k for k, i in enumerate(ids) if i != rec.sender]
            for n, q in enumerate(world):
                dist = np.hypot(*(pos[others] - q).T)
                k = others[int(np.argmin(dist))]
                true_v = pos[k] - np.array([x, y])
                d = float(np.hypot(*true_v))
                meas = float(np.hypot(*v[n]))
                if float(dist.min()) > GATE0 + GATE1 * d:
                    cols[0].append(math.nan)
                    cols[1].append(meas)
                    cols[2].append(math.nan)
                    cols[3].append(math.nan)
                    cols[4].append(math.nan)
                    cols[5].append(math.nan)
                    cols[6].append(math.nan)
                    continue
                beta_true = math.atan2(true_v[1], true_v[0]) - (
                    h - math.pi / 2
                )  # in i's fixed frame
                beta = math.atan2(v[n, 1], v[n, 0])
                cols[0].append(d)
                cols[1].append(meas)
                cols[2].append(meas - d)
                cols[3].append(d * float(_wrap(np.array(beta - beta_true))))
                # the mask as if its target stood at its start heading (nan: seen while
                # it turned; records without times: as recorded)
                target = core.get(ids[k])
                theta = mask_orientation(core[rec.sender], n, target)
                if math.isfinite(theta):
                    hj = run.truth[ids[k]][2]
                    # h_j - h_i = β_ij + θ_ij - π/2 (modulo π) in the fixed frame of i
                    want = (hj - h) - beta_true + math.pi / 2
                    cols[4].append(float(_wrap_half(np.array(theta - want))))
                    timed = core[rec.sender].seen_at is not None and target is not None \
                        and target.stances is not None  # fmt: skip
                    flip = abs(float(_wrap(np.array(theta - want)))) > math.pi / 2
                    cols[5].append(float(flip) if timed else math.nan)
                else:
                    cols[4].append(math.nan)
                    cols[5].append(math.nan)
                cols[6].append(mask_view(core[rec.sender], n))
    a = [np.array(c) for c in cols]
    return Matched(*a)


def reversal_by_view(flip: np.ndarray, view: np.ndarray, overall: float) -> tuple[float, ...]:
    """The front/back confusion rate of each bin of a mask's reading (``w180_view``): of
    the timed masks (``flip`` 0 or 1, nan: none) whose ``view`` falls in the bin, the
    share read the other way round, counted as ``(k + 1) / (n + 2)``; ``overall`` for a
    bin without a mask."""
    bins = np.array([view_bin(float(v)) for v in view], dtype=object)
    out = []
    for b in range(VIEW_BINS):
        mine = flip[(bins == b) & np.isfinite(flip)]
        out.append((float(mine.sum()) + 1.0) / (mine.size + 2.0) if mine.size else overall)
    return tuple(out)


def _robust_sigma(e: np.ndarray) -> float:
    return float(1.4826 * np.median(np.abs(e - np.median(e)))) if e.size else math.nan


def _abs_sigma(e: np.ndarray) -> float:
    """σ of the Gaussian whose |error| has the same median (robust to gross errors up to
    half of them: those are what ``p_reject`` counts)."""
    return float(np.median(np.abs(e)) / 0.6745) if e.size else math.nan


def binned(
    x: np.ndarray, y: np.ndarray, stat: Callable[[np.ndarray], Any], least: int = 10
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per distance bin of :data:`BINS` with at least ``least`` samples: the mean x, the
    statistic of y, and the count."""
    out: list[tuple[float, float, float]] = []
    for lo, hi in itertools.pairwise(BINS):
        inb = (x >= lo) & (x < hi)
        if inb.sum() >= least:
            out.append((float(np.mean(x[inb])), float(stat(y[inb])), float(inb.sum())))
    a = np.array(out, dtype=np.float64).reshape(-1, 3)
    return a[:, 0], a[:, 1], a[:, 2]


def _quadrature(x: np.ndarray, sigma: np.ndarray, w: np.ndarray) -> tuple[float, float]:
    """``(a, b)`` of ``σ(d)² = a² + (b·d²)²`` fitted to per-bin σ in relative terms (least
    squares on log σ, weighted by the bins' counts; scipy's ``least_squares``)."""
    from scipy.optimize import least_squares

    def res(p: np.ndarray) -> np.ndarray:
        model = np.hypot(p[0], p[1] * x**2)
        return np.asarray(np.sqrt(w) * (np.log(model) - np.log(sigma)))

    fit = least_squares(res, x0=[float(sigma.min()), 0.01], bounds=([1e-4, 0.0], [1.0, 1.0]))
    return float(fit.x[0]), float(fit.x[1])


def _line(x: np.ndarray, y: np.ndarray, w: np.ndarray) -> tuple[float, float]:
    """Weighted least-squares line y = a + b·x with a, b >= 0 (scipy's NNLS: a σ or a
    rate neither goes below zero nor falls with distance)."""
    from scipy.optimize import nnls

    a_mat = np.stack([np.ones_like(x), x], axis=1) * np.sqrt(w)[:, None]
    sol, _ = nnls(a_mat, y * np.sqrt(w))
    return float(sol[0]), float(sol[1])


def fit(m: Matched, runs: list[Run], corpus: str) -> tuple[SightingNoise, dict[str, np.ndarray]]:
    """The model of the module docstring, and its per-bin figures (for the plot)."""
    mk = m.mask[np.isfinite(m.mask)]
    sm = _robust_sigma(mk[np.abs(mk) < math.radians(20)])
    w0 = float(np.mean(np.abs(mk) <= 3 * sm))
    w90 = float(np.mean(np.abs(mk) >= math.pi / 2 - 3 * sm))
    fits, runs_kept = fitted(runs)
    dist, along, across = residuals(fits)
    x, sr, w = binned(dist, along, _abs_sigma)
    _, st, _ = binned(dist, across, _abs_sigma)
    r0, r1 = _quadrature(x, sr, w)
    t0, t1 = _quadrature(x, st, w)
    base = SightingNoise(
        r0=max(r0, 1e-3), r1=r1, t0=max(t0, 1e-3), t1=t1,
        g0=0.0, g1=0.0, sigma_mask=sm, w0=w0, w90=w90, sightings=int(dist.size), corpus=corpus,
    )  # fmt: skip
    ed, bad, wilks, timed, sd, slost = pair_rejections(fits, base, [r.records for r in runs_kept])
    sightings = sum(len(m.neighbours) for r in runs_kept for m in r.records)

    # the rate at which sound robots' masks agree on an offset the per-mask model cannot
    # explain (Wilks' p below TURNED_P), counted conservatively ((k + 1) / (n + 1))
    # the heading test's null scale, on the robots whose masks are turned back by the
    # records' times (the only ones an agent of today sees), then the rates of sound robots
    # seen turned as a whole beyond it: of timed records the share seen (0 when none is:
    # no mechanism remains once masks seen mid-turn are set aside); of records without
    # times counted conservatively, (k + 1) / (n + 1). A corpus without one kind keeps the
    # shipped figure of that kind.
    shipped = shipped_noise()
    wstat = chi2.isf(np.clip(wilks, 1e-300, 1.0), 1) * base.mask_scale  # Wilks' Λ, unscaled
    mscale = null_scale(wstat[timed], 1) if timed.any() else shipped.mask_scale
    p_scaled = chi2.sf(wstat / mscale, 1)
    rho = excess_rate(p_scaled[timed]) if timed.any() else shipped.rho
    untimed = p_scaled[~timed]
    rho_untimed = (
        (float((untimed < TURNED_P).sum()) + 1.0) / (len(untimed) + 1.0)
        if len(untimed)
        else shipped.rho_untimed
    )
    gc, gr, gn = binned(ed, bad, np.mean)
    g0, g1 = _line(gc, gr, gn)
    # lost strays per sighting of a sound robot: too few to bin by distance, one rate
    # (counted conservatively, (k + 1) / (n + 2))
    sc, sr_, sn = binned(sd, slost, np.mean)
    s0, s1 = (float(slost.sum()) + 1.0) / (float(sightings) + 2.0), 0.0
    # front/back confusion, of the masks turned back by the records' times
    flips = m.flip[np.isfinite(m.flip)]
    w180 = float(flips.mean()) if flips.size else shipped.w180
    w180_view = reversal_by_view(m.flip, m.view, w180)
    sent, lost = alone_losses(fits, replace(base, g0=g0, g1=g1), [r.records for r in runs_kept])
    a0 = (float(lost) + 1.0) / (float(sent) + 2.0)
    model = replace(base, g0=g0, g1=g1, rho=rho, rho_untimed=rho_untimed, mask_scale=mscale,
                    s0=s0, s1=s1, a0=a0, w180=w180, w180_view=w180_view,
                    bias_scale=bias_scale(fits, replace(base, g0=g0, g1=g1),
                                          [r.records for r in runs_kept]))  # fmt: skip
    bins = {"d": x, "sr": np.array(sr), "st": np.array(st), "n": w, "dist": dist, "along": along,
            "across": across, "gd": gc, "gross": gr, "gn": gn, "sd": sc, "stray": sr_, "sn": sn}  # fmt: skip
    return model, bins


#: The shipped model's fleets: the corpus's tuned-on fleets with a seed below this (the
#: later ones judge the model without having shaped it).
SHIPPED_SEEDS_BELOW = 1133
#: The tail quantiles at which the bias test's null is compared with χ²₃.
BIAS_QUANTILES = (0.9, 0.99)


def excess_rate(p: np.ndarray, level: float = 0.05) -> float:
    """The rate of sound robots seen turned beyond the model, from their heading-test
    p-values ``p``: the count ``k`` below :data:`TURNED_P` against the ``n·TURNED_P`` the
    model itself puts there. 0 when ``k`` is within that (a one-sided binomial test at
    ``level``: no evidence of a mechanism the model leaves out), else the excess
    ``(k − n·TURNED_P) / n``."""
    from scipy.stats import binom

    n, k = len(p), int((np.asarray(p) < TURNED_P).sum())
    if n == 0 or k == 0 or float(binom.sf(k - 1, n, TURNED_P)) >= level:
        return 0.0
    return (k - n * TURNED_P) / n


def null_scale(stats: np.ndarray, dof: int) -> float:
    """A test's null scale: the largest ratio, at :data:`BIAS_QUANTILES`, of its
    statistic over sound robots to χ²_dof's quantile, and never below 1 (a statistic with
    a lighter tail than χ²_dof keeps χ²_dof); 1 without statistics."""
    if stats.size == 0:
        return 1.0
    ratios = [float(np.quantile(stats, q)) / float(chi2.isf(1.0 - q, dof)) for q in BIAS_QUANTILES]
    return max(1.0, *ratios)


def bias_scale(
    fits: list[PoseFrame], model: SightingNoise, records: list[tuple[NeighborRecordMsg, ...]]
) -> float:
    """The bias test's null scale (:func:`null_scale`, χ²₃) over every robot of the
    fault-free fleets, each with its unpaired sightings as the agents test it."""
    from agent.core.formation.frame.faults.bias_test import bias_fit
    from agent.core.formation.frame.faults.fault_test import unpaired

    stats = []
    for f, recs in zip(fits, records, strict=True):
        loose = unpaired(f, FormationAdapter.records(recs))
        stats += [bias_fit(f, r, model, 1.0, loose.get(r)).statistic for r in f.ids]
    return null_scale(np.array(stats), 3)


def alone_losses(
    fits: list[PoseFrame], model: SightingNoise, records: list[tuple[NeighborRecordMsg, ...]]
) -> tuple[int, int]:
    """(sightings, lost) of every robot of the fault-free fleets tested alone against the
    others held at their fitted poses (:func:`agent.core.formation.frame.faults.alone.alone_test`),
    over the robots enough of the others' sightings place (the test's own rule)."""
    from agent.core.formation.frame.faults.alone import alone_test
    from agent.core.formation.frame.poses import evaluate_poses

    sent = lost = 0
    for f, recs in zip(fits, records, strict=True):
        own = FormationAdapter.records(recs)
        for k, rid in enumerate(f.ids):
            keep = [j for j in range(len(f.ids)) if j != k]
            ids = tuple(f.ids[j] for j in keep)
            rest = evaluate_poses(ids, (), f.positions[keep], f.headings[keep], ids[0])
            alone = alone_test(rest, own, rid, model)
            if alone.place is not None:
                sent += alone.test.strays
                lost += alone.test.lost
    return sent, lost


def fitted(runs: list[Run]) -> tuple[list[PoseFrame], list[Run]]:
    """Each run's records fitted as the agents fit them (runs that do not connect left
    out), and the runs kept."""
    from agent.core.formation.frame.neighbour_check import DEFAULT_EPSILON
    from agent.core.formation.frame.pose_pairing import identify_pairs
    from agent.core.formation.frame.poses import fit_from_graph

    out, kept = [], []
    for run in runs:
        try:
            recs = FormationAdapter.records(run.records)
            poses = fit_from_graph(identify_pairs(recs, DEFAULT_EPSILON))
        except ValueError:
            continue
        est = {i: (poses.positions[k], float(poses.headings[k])) for k, i in enumerate(poses.ids)}
        if frame_error(est, run.truth) <= (FRAME_POS, FRAME_PSI):
            out.append(poses)
            kept.append(run)
    return out, kept


def residuals(fits: list[PoseFrame]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every sighting's measured distance and its fit residual along and across its line
    of sight (owner's fixed frame)."""
    from agent.core.formation.frame.faults.fault_test import misfits

    parts = [split(*misfits(poses)) for poses in fits]
    d, along, across = (
        np.concatenate([p[k] for p in parts]) if parts else np.zeros(0) for k in range(3)
    )
    return d, along, across


def pair_rejections(
    fits: list[PoseFrame], noise: SightingNoise, records: list[tuple[NeighborRecordMsg, ...]]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Every pair of every fit: its mean sighting distance and whether the χ² test rejects
    it under ``noise``; every robot's heading-test p-value (Wilks') and whether its record
    carries times (stances); every stray sighting's distance and whether it is lost (lands
    on no robot)."""
    from agent.core.formation.frame.faults.fault_test import rejected_edges, strays
    from agent.core.formation.frame.faults.heading_test import mask_deltas, mask_test

    dist, bad, wilks, timed, sd, slost = [], [], [], [], [], []
    for poses, recs in zip(fits, records, strict=True):
        has_times = {m.sender for m in recs if m.stances}
        for row in strays(poses, FormationAdapter.records(recs), noise).values():
            for d_s, lands in row:
                sd.append(d_s)
                slost.append(float(not lands))
        d: dict[tuple[int, int], list[float]] = {}
        for mm in poses.measurements:
            d.setdefault((min(mm.owner, mm.target), max(mm.owner, mm.target)), []).append(
                float(np.hypot(*mm.vector))
            )
        for e, rejected in rejected_edges(poses, noise).items():
            dist.append(float(np.mean(d[e])))
            bad.append(float(rejected))
        for rid in poses.ids:
            deltas = mask_deltas(poses, rid)
            if deltas:
                wilks.append(mask_test(deltas, noise)[1])
                timed.append(rid in has_times)
    return (np.array(dist), np.array(bad), np.array(wilks), np.array(timed, dtype=bool),
            np.array(sd), np.array(slost))  # fmt: skip


def draw(m: Matched, model: SightingNoise, bins: dict[str, np.ndarray], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 4, figsize=(17, 4))
    d = np.linspace(0.4, 3.2, 50)
    ax[0].scatter(bins["dist"], bins["along"], s=3, alpha=0.3)
    for k in (-2, 2):
        ax[0].plot(d, k * model.sigma_radial(d), "k--", lw=0.8)
    ax[0].set(xlabel="distance (m)", ylabel="fit residual along the sight (m)", ylim=(-0.6, 0.6),
              title=f"σ_r² = {model.r0:.3f}² + ({model.r1:.4f}·d²)² (±2σ)")  # fmt: skip
    ax[1].scatter(bins["dist"], bins["across"], s=3, alpha=0.3)
    for k in (-2, 2):
        ax[1].plot(d, k * model.sigma_tangential(d), "k--", lw=0.8)
    ax[1].set(xlabel="distance (m)", ylabel="fit residual across it (m)", ylim=(-0.6, 0.6),
              title=f"σ_t² = {model.t0:.3f}² + ({model.t1:.4f}·d²)²")  # fmt: skip
    ax[2].bar(bins["gd"], bins["gross"], width=0.15)
    ax[2].plot(d, model.p_reject(d), "k--")
    ax[2].set(
        xlabel="pair distance (m)",
        ylabel="rejected share",
        title="sound pairs rejected by the χ² test",
    )
    mk = m.mask[np.isfinite(m.mask)]
    ax[3].hist(np.degrees(mk), bins=np.arange(-90, 91, 5), density=True, alpha=0.6)
    xs = np.linspace(-math.pi / 2, math.pi / 2, 361)
    ax[3].plot(np.degrees(xs), model.mask_density(xs) * math.pi / 180, "k-")
    ax[3].set(xlabel="mask error mod 180° (°)", ylabel="density (1/°)",
              title=f"σ_m {math.degrees(model.sigma_mask):.1f}°, w0 {model.w0:.2f}, w90 {model.w90:.2f}")  # fmt: skip
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def tuned_runs(root: Path, seeds_below: int | None = None) -> list[Run]:
    """The runs a model is fitted on: the fleets of ``root`` without a fault and not held
    out, with a seed below ``seeds_below`` (None: every one)."""
    return [
        r for r in load_corpus(root)
        if not r.fault and not held_out(r.seed) and (seeds_below is None or r.seed < seeds_below)
    ]  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m tools.fit_noise", description=(__doc__ or "").split("\n\n")[0]
    )
    ap.add_argument("--corpus", type=Path, default=Path("tests/data/frames"))
    ap.add_argument("--png", type=Path, default=Path("out/sighting_noise.png"))
    ap.add_argument("--write", action="store_true", help="write the shipped model file")
    ap.add_argument("--seeds-below", type=int, default=None, metavar="SEED",
                    help="only the fleets whose seed is below SEED (the shipped model: "
                         f"{SHIPPED_SEEDS_BELOW})")  # fmt: skip
    a = ap.parse_args(argv)
    runs = tuned_runs(a.corpus, a.seeds_below)
    below = "" if a.seeds_below is None else f", seeds below {a.seeds_below}"
    m = match(runs)
    model, bins = fit(m, runs, f"{a.corpus} ({len(runs)} fleets{below}, held-out fleets excluded)")
    n = len(m.distance)
    print(f"{len(runs)} fleets, {n} sightings, {int(np.isfinite(m.distance).sum())} matched")
    for k in range(len(bins["d"])):
        print(
            f"  d {bins['d'][k]:.2f} m: σ_r {bins['sr'][k]:.3f} σ_t {bins['st'][k]:.3f} (n {int(bins['n'][k])})"
        )
    for k in range(len(bins["sd"])):
        print(
            f"  strays at {bins['sd'][k]:.2f} m: {bins['stray'][k]:.3f} lost (n {int(bins['sn'][k])})"
        )
    for k in range(len(bins["gd"])):
        print(
            f"  pairs at {bins['gd'][k]:.2f} m: {bins['gross'][k]:.3f} rejected (n {int(bins['gn'][k])})"
        )
    print(model)
    draw(m, model, bins, a.png)
    print(f"figure: {a.png}")
    if a.write:
        print(f"written: {model.save()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
