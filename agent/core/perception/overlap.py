"""Splitting tuples merged by overlapping NAOs (NAO paper section 6, first cause of failure).

When one NAO stands partly behind another, an orange part of the one behind touches an
orange part of the one in front in the image, and segmentation (3.1.1) returns them as
one connected component: neither NAO's tuple group then looks like a mask of the M-base.
The parts of a NAO are compact (spherical shoulder covers, a cylindrical head cap), so
two merged parts meet at a *neck* narrower than either part, or at least at two concave
corners of the outline. A component whose shape is not convex is eroded step by step
(thresholds of its distance transform); at the first step where it falls apart into two
or more cores, each both wider than the neck by ``NECK_RATIO``, its pixels are given to
the nearest core. Failing that, it is cut along the straight line between the two
deepest concavities of its outline (convexity defects at least ``DEFECT_MIN`` px deep:
a small far shoulder cover half inside a near one, or a far head cap's band abutting a
near one at another height). The pieces become extra tuples
*beside* the component (recognition keeps both readings and never puts a component and
one of its own pieces into the same group), so a NAO whose own parts happen to form a
non-convex blob is still recognised whole.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from agent.core.perception.segmentation import Tuple

MIN_AREA = 30  # px: smaller components are not split
MAX_SOLIDITY = 0.97  # area / convex hull area: more compact components are not split
NECK_RATIO = 1.15  # a core's half-width (distance-transform peak) over the neck's
MIN_PIECE = 12  # px: smallest piece kept (the tuples' min_area)
MAX_PIECES = 3
DEFECT_MIN = 2.0  # px: depth of a concavity of the outline that may start a cut
MAX_SOLIDITY_CUT = 0.99  # components more compact than this are not cut


@dataclass(frozen=True)
class Pieces:
    """A label image with every piece labelled, the tuples (components and pieces) and,
    per tuple, its atoms: the piece labels it covers (a piece: itself; a split component:
    all its pieces; an unsplit component: its own label)."""

    labels: np.ndarray
    tuples: list[Tuple]
    atoms: list[tuple[int, ...]]
    parent: list[int]  # per tuple: the index of the component it was cut from (itself if none)


def _nearest(comp: np.ndarray, seeds: np.ndarray) -> np.ndarray:
    """Give every pixel of ``comp`` the label of the nearest labelled seed pixel."""
    inv = (seeds == 0).astype(np.uint8)
    _, near = cv2.distanceTransformWithLabels(inv, cv2.DIST_L2, 3, labelType=cv2.DIST_LABEL_PIXEL)
    ys, xs = np.nonzero(seeds)
    lut = np.zeros(int(near.max()) + 1, dtype=np.int32)
    lut[near[ys, xs]] = seeds[ys, xs]
    return np.where(comp > 0, lut[near], 0).astype(np.int32)


def _cut_defects(comp: np.ndarray) -> np.ndarray | None:
    """Cut ``comp`` between its two deepest concavities; piece labels or None."""
    cnts, _ = cv2.findContours(comp, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not cnts:
        return None
    c = max(cnts, key=cv2.contourArea)
    if len(c) < 8:
        return None
    hull = cv2.convexHull(c, returnPoints=False)
    try:
        defects = cv2.convexityDefects(c, hull)
    except cv2.error:  # self-intersecting outline after approximation
        return None
    if defects is None:
        return None
    deep = sorted(
        (d for d in defects.reshape(-1, 4) if d[3] / 256.0 >= DEFECT_MIN),
        key=lambda d: (-int(d[3]), int(d[2])),
    )
    if len(deep) < 2:
        return None
    a = tuple(int(v) for v in c[deep[0][2], 0])
    b = tuple(int(v) for v in c[deep[1][2], 0])
    cut = comp.copy()
    cv2.line(cut, a, b, 0, 2)
    n, lab, stats, _ = cv2.connectedComponentsWithStats(cut, connectivity=4)
    big = [i for i in range(1, n) if stats[i, cv2.CC_STAT_AREA] >= MIN_PIECE]
    if len(big) < 2:
        return None
    seeds = np.zeros(comp.shape, dtype=np.int32)
    for j, i in enumerate(big[:MAX_PIECES]):
        seeds[lab == i] = j + 1
    return _nearest(comp, seeds)


def _split_one(comp: np.ndarray, solidity: float) -> np.ndarray | None:
    """Piece labels (1..k) of one component's 0/1 crop, or None if it does not split."""
    if solidity < MAX_SOLIDITY:
        parts = _split_neck(comp)
        if parts is not None:
            return parts
    return _cut_defects(comp) if solidity < MAX_SOLIDITY_CUT else None


def _split_neck(comp: np.ndarray) -> np.ndarray | None:
    """Split ``comp`` at a neck of its distance transform; piece labels or None."""
    dist = cv2.distanceTransform(comp, cv2.DIST_L2, 3)
    peak = float(dist.max())
    t = 1.0
    while t * NECK_RATIO < peak:
        cores = (dist > t).astype(np.uint8)
        n, lab, stats, _ = cv2.connectedComponentsWithStats(cores, connectivity=8)
        if n > 2:
            big = [
                i
                for i in range(1, n)
                if float(dist[lab == i].max()) >= t * NECK_RATIO and stats[i, cv2.CC_STAT_AREA] >= 2
            ]
            if len(big) >= 2:
                seeds = np.zeros_like(comp, dtype=np.int32)
                for j, i in enumerate(big[:MAX_PIECES]):
                    seeds[lab == i] = j + 1
                return _nearest(comp, seeds)  # each pixel goes to the nearest core
        t += 1.0
    return None


def split_merged(labels: np.ndarray, tuples: list[Tuple]) -> Pieces:
    """Components plus the pieces of those that split at a neck (see the module docs).

    The order is deterministic: the input tuples first (in their order), then the pieces
    of each split component in the order of the components, each piece list sorted by
    (box x, box y).
    """
    if labels.ndim != 2:
        raise ValueError("labels must be a 2-D label image")
    out_labels = labels.copy()
    out: list[Tuple] = list(tuples)
    atoms: list[tuple[int, ...]] = [(t.label,) for t in tuples]
    parent = list(range(len(tuples)))
    next_label = int(labels.max()) + 1 if labels.size else 1
    for ti, t in enumerate(tuples):
        if t.area < MIN_AREA:
            continue
        x, y, w, h = t.box
        comp = (labels[y : y + h, x : x + w] == t.label).astype(np.uint8)
        cnts, _ = cv2.findContours(comp, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        hull = cv2.convexHull(np.vstack(cnts))
        parts = _split_one(comp, t.area / max(float(cv2.contourArea(hull)), 1.0))
        if parts is None:
            continue
        new: list[Tuple] = []
        for j in range(1, int(parts.max()) + 1):
            sel = parts == j
            area = int(sel.sum())
            if area < MIN_PIECE:
                continue
            ys, xs = np.nonzero(sel)
            sub = out_labels[y : y + h, x : x + w]
            sub[sel] = next_label
            new.append(
                Tuple(
                    label=next_label,
                    cx=float(x + xs.mean()),
                    cy=float(y + ys.mean()),
                    box=(
                        int(x + xs.min()),
                        int(y + ys.min()),
                        int(xs.max() - xs.min() + 1),
                        int(ys.max() - ys.min() + 1),
                    ),
                    area=area,
                )
            )
            next_label += 1
        if len(new) < 2:
            # a piece too small to keep: its pixels stay in the component's label
            for p in new:
                sub = out_labels[y : y + h, x : x + w]
                sub[sub == p.label] = t.label
            continue
        new.sort(key=lambda p: (p.box[0], p.box[1], p.label))
        # pixels of dropped tiny pieces keep the component's label, so the atoms of the
        # component are its pieces plus its own label
        atoms[ti] = (t.label, *(p.label for p in new))
        for p in new:
            out.append(p)
            atoms.append((p.label,))
            parent.append(ti)
    return Pieces(out_labels, out, atoms, parent)
