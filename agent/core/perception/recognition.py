"""Recognition of NAOs by cross-correlation with the M-base (NAO paper 3.1.3, Algorithm 1).

Every group of 3 tuples (2 for the side postures) is compared with every mask at the
scale r_g at which the mask just fits into the group's box (Algorithm 1 grows r_g in
steps of 0.01 until the scaled mask would exceed the group), and the confidence of the
best mask is λ. The group is an NAO when λ >= λ_th = 0.6 (0.8 for a 2-tuple group: a
side posture has fewer features, 5.2.2 (i), and pairs of orange clutter mimic it).

Confidence. The paper's λ = sqrt(a/b) with a = (f*g), b = (f*f) saturates at 1 for any
orange blob that covers the mask, which would make clutter look like NAOs. We use the
normalised cross-correlation λ = a / sqrt(b·c) with c = (g*g), which equals the paper's
λ when the group is exactly the mask and also penalises group pixels the mask lacks.

Speed. :func:`reference_scores` is Algorithm 1 as written (loop over scales, resize,
correlate over every placement). :func:`fast_scores` gives the same answers in one
matrix product: the group crop and every mask are resampled once to a common
``CANON_W x CANON_H`` size (unit vectors), their dot product is the correlation at the
matched scale, and the aspect-ratio mismatch that the uniform scaling of Algorithm 1
leaves uncovered is charged as sqrt(min(ar_g/ar_m, ar_m/ar_g)); r_g = min(w_g/w_m,
h_g/h_m) is Algorithm 1's scale without the 0.01 quantisation. A test shows both pick
the same mask with λ and r_g within small tolerances.

Tie-breaks (documented for determinism): groups are enumerated in the order of the
sorted tuples (by box x, y, label); the best mask of a group is the lowest index among
equal λ (``argmax``); accepted groups are taken greedily by decreasing λ, then more
tuples, then box x, then box y, and a pixel (a tuple, or a piece of a tuple split by
:mod:`agent.core.perception.overlap`) belongs to at most one NAO.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import cv2
import numpy as np

from agent.core.perception.mbase import CANON_H, CANON_W, MBase
from agent.core.perception.segmentation import Tuple

LAMBDA_TH = 0.6
# A 2-tuple group (side posture) has fewer features, so lookalikes match it more easily
# (paper 5.2.2 (i)); it must reach this stricter confidence. Measured on 450 views
# (seeds 11, 12, 201): true 2-tuple matches have λ >= 0.8 in 98.6 % of cases, pairs of
# clutter cubes reached 0.73-0.77.
LAMBDA_TH_PAIR = 0.8
SCALE_MIN = 0.01
SCALE_MAX = 1.5
SCALE_STEP = 0.01
MAX_TUPLES = 24
RG_MIN = 0.15  # scale gate of the candidate groups: NAOs up to about 3.5 m
RG_MAX = 1.5
# The group's top row must lie within TOP_TOL·h + TOP_PX of the matched mask's top at r_g
# (the camera height and pitch are fixed). Measured on 520 true matches at 0.5-3 m
# (seeds 501, 502): |offset| <= 0.12·h; orange clutter pairs floating above or below the
# NAOs' band lie further off.
TOP_TOL = 0.15
TOP_PX = 3.0
# A weak match (λ < LAMBDA_SHARES) must also split its area among its tuples as the
# mask does: the largest deviation of the sorted area shares at most SHARE_TOL (clutter
# triples of a big and two small cubes reach λ 0.6 at 48x32 but not these shares).
LAMBDA_SHARES = 0.7
SHARE_TOL = 0.3


@dataclass(frozen=True)
class Match:
    """An accepted tuple group: the tuple indices, the mask, λ, r_g and the group's box."""

    tuples: tuple[int, ...]
    mask: int
    confidence: float
    scale: float
    box: tuple[int, int, int, int]


def group_box(tuples: list[Tuple], group: tuple[int, ...]) -> tuple[int, int, int, int]:
    """Union of the boxes of the tuples in ``group`` as (x, y, w, h)."""
    x0 = min(tuples[i].box[0] for i in group)
    y0 = min(tuples[i].box[1] for i in group)
    x1 = max(tuples[i].box[0] + tuples[i].box[2] for i in group)
    y1 = max(tuples[i].box[1] + tuples[i].box[3] for i in group)
    return x0, y0, x1 - x0, y1 - y0


def group_crop(
    labels: np.ndarray,
    tuples: list[Tuple],
    group: tuple[int, ...],
    subsample: bool = False,
    atoms: list[tuple[int, ...]] | None = None,
) -> np.ndarray:
    """The 0/1 image of only the group's tuples inside the group's box (g[x, y] of eq. 1).

    ``subsample`` takes every s-th pixel of a box more than 4x the canonical size (s >= 2),
    which changes its canonical resampling by well under a pixel. ``atoms`` gives the
    labels each tuple covers (see :mod:`agent.core.perception.overlap`; default: its own).
    """
    x, y, w, h = group_box(tuples, group)
    step = max(1, min(w // (4 * CANON_W), h // (4 * CANON_H))) if subsample else 1
    sub = labels[y : y + h : step, x : x + w : step]
    if atoms is None:
        ids = [tuples[i].label for i in group]
    else:
        ids = [a for i in group for a in atoms[i]]
    lut = np.zeros(max(ids) + 1, dtype=np.uint8)
    lut[ids] = 1
    return lut[np.minimum(sub, max(ids))] if sub.size else sub.astype(np.uint8)


def candidate_groups(
    tuples: list[Tuple], mbase: MBase, horizon_row: float, parent: list[int] | None = None
) -> list[tuple[int, ...]]:
    """Tuple groups worth scoring: 3-groups (and 2-groups, for the masks with 2 tuples)
    whose box size, aspect and height above the horizon could be an NAO at r_g in
    [RG_MIN, RG_MAX] = [0.15, 1.5] (about 0.4-3.5 m) (vectorised over all combinations).

    These gates only drop groups that no mask could match at a plausible distance; they
    never decide between masks. ``parent[i]`` is the component tuple i was cut from
    (:mod:`agent.core.perception.overlap`; itself if whole): a group never holds a component
    and one of its own pieces. Groups come out in combination order.
    """
    if len(tuples) > MAX_TUPLES:  # keep the largest tuples; ties by the sorted order
        keep = sorted(range(len(tuples)), key=lambda i: (-tuples[i].area, i))[:MAX_TUPLES]
        idx = sorted(keep)
    else:
        idx = list(range(len(tuples)))
    boxes = np.array([tuples[i].box for i in idx], dtype=np.float64).reshape(-1, 4)
    x0, y0 = boxes[:, 0], boxes[:, 1]
    x1, y1 = x0 + boxes[:, 2], y0 + boxes[:, 3]
    out: list[tuple[int, ...]] = []
    for n in sorted({int(v) for v in mbase.n_tuples}, reverse=True):
        sel = mbase.n_tuples == n
        if n > len(idx) or not np.any(sel):
            continue
        combos = np.array(list(itertools.combinations(range(len(idx)), n)), dtype=np.int64)
        if parent is not None:
            fam = np.array([parent[i] for i in idx], dtype=np.int64)[combos]
            whole = fam == np.array(idx, dtype=np.int64)[combos]
            clash = np.zeros(len(combos), dtype=bool)
            for a, b in itertools.combinations(range(n), 2):
                clash |= (fam[:, a] == fam[:, b]) & (whole[:, a] | whole[:, b])
            combos = combos[~clash]
            if not len(combos):
                continue
        gx0, gy0 = x0[combos].min(axis=1), y0[combos].min(axis=1)
        w = x1[combos].max(axis=1) - gx0
        h = y1[combos].max(axis=1) - gy0
        sizes = mbase.sizes[sel]
        # per (group, mask): scale in [RG_MIN, RG_MAX] on both sides, aspect within 0.75-1.33
        # and the crop's top where the mask's top would be at this size
        rw = w[:, None] / sizes[None, :, 0]
        rh = h[:, None] / sizes[None, :, 1]
        expect = horizon_row + rh * mbase.top_offset[sel][None, :]
        ok = (
            (rw >= RG_MIN)
            & (rw <= RG_MAX)
            & (rh >= RG_MIN)
            & (rh <= RG_MAX)
            & (rw / rh >= 0.75)
            & (rw / rh <= 1.33)
            & (np.abs(gy0[:, None] - expect) <= TOP_TOL * h[:, None] + TOP_PX)
        ).any(axis=1)
        out.extend(tuple(idx[int(i)] for i in c) for c in combos[ok])
    return out


def fast_scores(
    crops: list[np.ndarray],
    mbase: MBase,
    sizes_px: list[tuple[int, int]] | None = None,
    counts: list[int] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """λ and r_g of every crop against every mask, shapes (G, K), vectorised.

    ``sizes_px`` are the groups' box sizes (w, h) when the crops were subsampled. With
    ``counts`` (tuples per crop) only masks with as many tuples are correlated (λ = 0
    for the others), which saves most of the product.
    """
    if not crops:
        return np.zeros((0, len(mbase))), np.zeros((0, len(mbase)))
    vecs = np.empty((len(crops), CANON_W * CANON_H), dtype=np.float32)
    sizes = np.empty((len(crops), 2))
    for i, c in enumerate(crops):
        if c.ndim != 2 or c.size == 0:
            raise ValueError(f"crop {i} must be a non-empty 2-D array")
        small = cv2.resize(c.astype(np.float32), (CANON_W, CANON_H), interpolation=cv2.INTER_AREA)
        v = small.reshape(-1)
        n = float(np.sqrt(np.dot(v, v)))
        vecs[i] = v / n if n > 0 else 0.0
        sizes[i] = (c.shape[1], c.shape[0]) if sizes_px is None else sizes_px[i]
    if counts is not None and len(counts) != len(crops):
        raise ValueError(f"{len(counts)} counts for {len(crops)} crops")
    ncc = np.zeros((len(crops), len(mbase)))
    if counts is None:
        blocks = [(np.arange(len(crops)), np.arange(len(mbase)))]
    else:
        cnt = np.asarray(counts)
        blocks = [
            (np.flatnonzero(cnt == n), np.flatnonzero(mbase.n_tuples == n))
            for n in sorted(set(counts))
        ]
    for rows, cols in blocks:
        if not len(rows) or not len(cols):
            continue
        # cv2.gemm: one small single-call product, no BLAS thread pool to wake up
        part = cv2.gemm(  # type: ignore[call-overload]
            vecs[rows], mbase.canon32[cols], 1.0, None, 0.0, flags=cv2.GEMM_2_T
        )
        ncc[np.ix_(rows, cols)] = part
    ar_g = (sizes[:, 0] / sizes[:, 1])[:, None]
    ar_m = (mbase.sizes[:, 0] / mbase.sizes[:, 1])[None, :]
    aspect = np.sqrt(np.minimum(ar_g / ar_m, ar_m / ar_g))
    rg = np.minimum(
        sizes[:, 0:1] / mbase.sizes[None, :, 0], sizes[:, 1:2] / mbase.sizes[None, :, 1]
    )
    return np.clip(ncc * aspect, 0.0, 1.0), rg


def reference_scores(crop: np.ndarray, mbase: MBase, k: int) -> tuple[float, float]:
    """Algorithm 1 as written for one crop and mask ``k``: λ and r_g (slow; for tests)."""
    if crop.ndim != 2 or crop.size == 0:
        raise ValueError("crop must be a non-empty 2-D array")
    if not 0 <= k < len(mbase):
        raise ValueError(f"mask index {k} outside [0, {len(mbase)})")
    gh, gw = crop.shape
    mh, mw = mbase.masks[k].shape
    rg = 0.0
    for step in range(round(SCALE_MIN / SCALE_STEP), round(SCALE_MAX / SCALE_STEP) + 1):
        s = step * SCALE_STEP
        if round(mw * s) > gw or round(mh * s) > gh:
            break
        rg = s
    if rg == 0.0:
        return 0.0, 0.0
    dim = (max(1, round(mw * rg)), max(1, round(mh * rg)))
    f = cv2.resize(mbase.masks[k].astype(np.float32), dim, interpolation=cv2.INTER_AREA)
    g = crop.astype(np.float32)
    a = float(cv2.matchTemplate(g, f, cv2.TM_CCORR).max())  # eq. 1 at every placement
    b = float((f * f).sum())
    c = float((g * g).sum())
    if b <= 0 or c <= 0:
        return 0.0, rg
    return min(1.0, a / np.sqrt(b * c)), rg


def leaves_sibling_inside(
    tuples: list[Tuple], group: tuple[int, ...], parent: list[int], box: tuple[int, int, int, int]
) -> bool:
    """Whether the group uses a piece of a split component but leaves out another piece
    of it whose centre lies inside the group's box. A split is only meant to give away
    the part of another NAO, which lies outside this NAO's box; a NAO that keeps only
    some pieces of its own turned head cap is a wrong reading."""
    x, y, w, h = box
    for i in group:
        if parent[i] == i:
            continue
        for j, pj in enumerate(parent):
            if pj == parent[i] and j != pj and j not in group:
                t = tuples[j]
                if x <= t.cx < x + w and y <= t.cy < y + h:
                    return True
    return False


def share_gap(tuples: list[Tuple], group: tuple[int, ...], mbase: MBase, k: int) -> float:
    """Largest difference between the group's and mask k's tuple area shares (each sorted
    from the largest tuple down); 1 when their tuple counts differ."""
    areas = np.sort(np.array([tuples[i].area for i in group], dtype=np.float64))[::-1]
    shares = mbase.part_shares[k]
    if len(areas) != len(shares) or areas.sum() <= 0:
        return 1.0
    return float(np.max(np.abs(areas / areas.sum() - shares)))


def recognise(
    labels: np.ndarray,
    tuples: list[Tuple],
    mbase: MBase,
    horizon_row: float,
    threshold: float = LAMBDA_TH,
    atoms: list[tuple[int, ...]] | None = None,
    parent: list[int] | None = None,
) -> list[Match]:
    """Every NAO in one (cylindrical) label image, as accepted tuple groups.

    ``atoms`` and ``parent`` describe tuples cut from merged components
    (:func:`agent.core.perception.overlap.split_merged`); a pixel belongs to at most one NAO.
    """
    if not 0.0 < threshold <= 1.0:
        raise ValueError(f"threshold must be in (0, 1], got {threshold}")
    if (atoms is None) != (parent is None) or (
        atoms is not None and parent is not None and not len(atoms) == len(parent) == len(tuples)
    ):
        raise ValueError("atoms and parent must both be given, one entry per tuple")
    groups = candidate_groups(tuples, mbase, horizon_row, parent)
    if not groups:
        return []
    crops = [group_crop(labels, tuples, g, subsample=True, atoms=atoms) for g in groups]
    boxes = [group_box(tuples, g) for g in groups]
    lam, rg = fast_scores(crops, mbase, [(b[2], b[3]) for b in boxes], [len(g) for g in groups])
    # the box top must sit where the chosen mask's top sits at that scale
    tops = np.array([b[1] for b in boxes], dtype=np.float64)
    heights = np.array([b[3] for b in boxes], dtype=np.float64)
    expect = horizon_row + rg * mbase.top_offset[None, :]
    lam = np.where(np.abs(tops[:, None] - expect) <= TOP_TOL * heights[:, None] + TOP_PX, lam, 0.0)
    best = np.argmax(lam, axis=1)
    cand = []
    for gi, g in enumerate(groups):
        k = int(best[gi])
        v = float(lam[gi, k])
        if v < LAMBDA_SHARES and share_gap(tuples, g, mbase, k) > SHARE_TOL:
            continue
        if v >= (max(threshold, LAMBDA_TH_PAIR) if len(g) == 2 else threshold):
            box = group_box(tuples, g)
            if parent is not None and leaves_sibling_inside(tuples, g, parent, box):
                continue
            cand.append((-v, -len(g), box[0], box[1], gi, k))
    cand.sort()
    used: set[int] = set()
    out: list[Match] = []
    for _, _, _, _, gi, k in cand:
        g = groups[gi]
        ga = {a for i in g for a in (atoms[i] if atoms is not None else (tuples[i].label,))}
        if used.intersection(ga):
            continue
        used.update(ga)
        out.append(Match(g, k, float(lam[gi, k]), float(rg[gi, k]), group_box(tuples, g)))
    return out
