"""Bundle lanes: robots that walk along the pyramid's axis past each other's starts get a
lane each, between two slot columns (to bring the planner's worst makespan to at most 2× CAPT's; our
addition to NAO paper 4.2's straight paths, in the plan of docs/design.md §1 (step 5), kept
to the safety rule of :mod:`safety` by the scheduler as every via point is).

The worst fleet of ``python -m tools.bench plan`` is a line of 100 robots along the
pyramid's axis: ~40 of them walk from one end of the line to the pyramid, ~35 from the
other. Straight paths (or the start sidesteps of :mod:`kinks`) run over the slots of
the robots ahead of them, so a robot may only start once the one ahead is past its slot
(with speed-independent safety it could otherwise catch it up): chains of three and
more long walks. Here every robot of such a *bundle* walks in a lane parallel to the
axis instead.

Geometry (pyramid frame, y = the axis; AUV eq. 7): the slots of one layer are
2·d_e·sin φ_e apart and consecutive layers are offset by d_e·sin φ_e, so every slot's x
lies on one grid of step ``2h = d_e·sin φ_e``. A lane is a line x = const half-way
between two grid columns: it passes every slot at >= h, clear of it when h >= the
clearance (``LANE_GAP``). Any other shape: 2h is the smallest gap between two of its
slot columns, and a lane h beside a slot's column is >= h from every slot too. A robot with start (x0, y0), lane L and slot (xs, ys),
|L - xs| = h, walks

    (x0, y0) -> (L, y0 + e·|L - x0| / LANE_SLOPE) -> (L, ys) -> (xs, ys),

e = ±1 its direction along the axis: a step out to the lane (the *staircase*: the lane
is reached within |L - x0| / LANE_SLOPE along the axis), the lane, and a step of h
into the slot. Lanes closer than ``LANE_CLEAR`` clearances to the x of a bundle start
are not used (they would run over the starts ahead).

Which robot in which lane. A bundle is the robots that walk the same way along the
axis (e) to the slots of the given pairing (so that each robot is re-paired once, by
its own bundle) and whose straight path, >= ``LANE_MIN_LENGTH`` clearances long and at
least twice as long along the axis as across it, passes within ``LANE_NEAR`` clearances
of another start ahead of it. Its slots stay its slots; each picks one of its two lanes,
outermost slot first (by |xs - xc|, xc the median x of the bundle's starts; then the
deeper, then the slot order): its outer lane, unless that one already holds more of the
bundle's robots than the inner one (a tie: outer). Then robots and slots are paired
again (the bundle's slots permuted among its robots): robots nearest the pyramid first
(by y0 along e, then row), slots by their lane's |L - xc| (inner lanes first, then L),
then the deepest first (the robot that enters a lane first goes deepest: the one
behind it need only wait until it is past its own slot), then xs, then slot order; each
robot in turn takes the first free slot of that order that lies ahead of it along e.
When every slot lies ahead of every robot, the two orders are zipped: the farther
robots take outer lanes and step out further before the nearer robots' starts, and no
two lanes cross. A robot that starts among the slot rows (a line centred on the shape)
skips the slots behind it instead of walking against its bundle. ``joint=False``
pairs each side (L >= xc or not) on its own, with the robots whose original slot's lane
lies on that side; ``joint=True`` pairs the whole bundle at once. A robot whose step to the lane would reach its slot's
row keeps its straight path; so does a robot whose slot has no usable lane.

Robots that share a lane still wait for each other, and the robots standing between
the lanes (on the axis inside the pyramid) are ordered by the scheduler: the plan is
one candidate of :mod:`choice`, kept only when its makespan is strictly smaller.
"""

from __future__ import annotations

import math

import numpy as np

from agent.core.formation.paths.geometry import point_seg_dist
from agent.core.formation.shape.pyramid import check_geometry

#: Only straight paths at least this many clearances long get a lane.
LANE_MIN_LENGTH = 20.0
#: A path "runs past" a start that lies within this many clearances of it.
LANE_NEAR = 2.0
#: The step out to the lane: across / along the axis.
LANE_SLOPE = 0.45
#: A lane keeps this many clearances from the x of every start of its bundle.
LANE_CLEAR = 1.5
#: Lanes need h (half the column step) >= this many clearances.
LANE_GAP = 1.2


def lane_rows(starts_p: np.ndarray, targets_p: np.ndarray, clearance: float) -> np.ndarray:
    """Rows whose straight path (pyramid frame) is >= LANE_MIN_LENGTH clearances long,
    runs along the axis (|dy| >= 2|dx|) and passes within LANE_NEAR clearances of
    another start ahead of it (ascending)."""
    p = np.asarray(starts_p, dtype=np.float64)
    q = np.asarray(targets_p, dtype=np.float64)
    d = q - p
    length = np.hypot(d[:, 0], d[:, 1])
    cand = np.flatnonzero(
        (length >= LANE_MIN_LENGTH * clearance) & (np.abs(d[:, 1]) >= 2.0 * np.abs(d[:, 0]))
    )
    if cand.size == 0 or p.shape[0] < 2:
        return np.zeros(0, dtype=np.int64)
    dist = point_seg_dist(p[None, :, :], p[cand, None, :], q[cand, None, :])
    dist[np.arange(cand.size), cand] = np.inf
    ahead = np.einsum("kjd,kd->kj", p[None, :, :] - p[cand, None, :], d[cand])
    near = ((dist < LANE_NEAR * clearance) & (ahead > 0.0)).any(axis=1)
    return np.asarray(cand[near], dtype=np.int64)


def _pick_lanes(
    slots: list[int], s: np.ndarray, xc: float, h: float, x0: np.ndarray, clearance: float, e: float
) -> dict[int, float]:
    """Slot -> its lane (the module doc's rule); slots without a usable lane are left out.
    Lanes are rounded to 1e-9 m so that the lane of two neighbouring columns is one."""
    seq = sorted(slots, key=lambda k: (-abs(float(s[k, 0]) - xc), -e * float(s[k, 1]), k))
    used: dict[float, int] = {}
    out: dict[int, float] = {}
    for k in seq:
        xs = float(s[k, 0])
        side = 1.0 if xs >= xc else -1.0
        opts = [round(xs + side * h, 9), round(xs - side * h, 9)]
        opts = [ln for ln in opts if float(np.min(np.abs(ln - x0))) >= LANE_CLEAR * clearance]
        if not opts:
            continue
        ln = opts[1] if len(opts) == 2 and used.get(opts[0], 0) > used.get(opts[1], 0) else opts[0]
        out[k] = ln
        used[ln] = used.get(ln, 0) + 1
    return out


def _pair(
    robots: list[int], ks: list[int], p: np.ndarray, s: np.ndarray, e: float
) -> list[tuple[int, int]]:
    """Robots (nearest the shape first) paired with the slots ``ks`` (in the module doc's
    order): each takes the first free slot ahead of it along e. When every slot lies
    ahead of every robot this is the two orders zipped. A robot that starts among the
    slot rows (a line centred on the shape) has fewer slots ahead of it than one behind
    it: the slots ahead of the robots are nested sets, the nearest robot's the smallest,
    so taking the first of them leaves a slot ahead for every robot after it (the given
    pairing is one: every robot of a bundle walks its way)."""
    free = list(ks)
    out: list[tuple[int, int]] = []
    for i in robots:
        y_i = float(p[i, 1])
        k = next(k for k in free if e * (float(s[k, 1]) - y_i) > 0.0)  # never empty (above)
        free.remove(k)
        out.append((i, k))
    return out


def checked_rows(
    starts_p: np.ndarray, slots_p: np.ndarray, order: np.ndarray, clearance: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(starts, slots, order) as arrays, checked: (n, 2) starts and slots, ``order`` a
    permutation of range(n), ``clearance`` a finite distance > 0 (``ValueError``
    otherwise); the input check of every lane layout (:mod:`row_lanes`, :mod:`row_shift`
    too)."""
    p = np.asarray(starts_p, dtype=np.float64)
    s = np.asarray(slots_p, dtype=np.float64)
    perm = np.asarray(order)
    if p.ndim != 2 or p.shape[1:] != (2,) or s.shape != p.shape:
        raise ValueError(f"starts and slots must be (n, 2) arrays, got {p.shape} and {s.shape}")
    n = p.shape[0]
    if perm.shape != (n,) or not np.array_equal(np.sort(perm), np.arange(n)):
        raise ValueError(f"order must be a permutation of range({n})")
    if not (math.isfinite(clearance) and clearance > 0):
        raise ValueError(f"clearance must be a finite distance > 0, got {clearance!r}")
    return p, s, perm


def bundle_lanes(
    starts_p: np.ndarray,
    slots_p: np.ndarray,
    order: np.ndarray,
    d_e: float,
    phi_e: float,
    clearance: float,
    joint: bool = False,
    step: float | None = None,
) -> tuple[np.ndarray, list[tuple[np.ndarray, ...]]] | None:
    """The lane plan of the module doc, in the pyramid frame: (slot order per robot row,
    via points per row), or None when no robot gets a lane (h < LANE_GAP clearances, no
    bundle). ``order``: each row's slot (a permutation of the rows of ``slots_p``).
    ``step``: the smallest gap between two slot columns of another shape
    (:func:`agent.core.formation.shape.layout.column_step`; h = step / 2 keeps every lane
    at >= h from every slot, whatever the columns' spacing); default the pyramid's
    d_e·sin φ_e."""
    p, s, perm = checked_rows(starts_p, slots_p, order, clearance)
    n = p.shape[0]
    check_geometry(d_e, phi_e)
    out_order = perm.astype(np.int64).copy()
    if step is not None and not (math.isfinite(step) and step > 0):
        raise ValueError(f"the column step must be a finite distance > 0, got {step!r}")
    h = 0.5 * (d_e * math.sin(phi_e) if step is None else step)
    vias: list[tuple[np.ndarray, ...]] = [() for _ in range(n)]
    if h < LANE_GAP * clearance:
        return None
    rows = lane_rows(p, s[out_order], clearance)
    changed = False
    for e in (-1.0, 1.0):
        # the bundle of the given pairing, so that no robot is re-paired twice
        bundle = [int(i) for i in rows if (s[perm[i], 1] - p[i, 1]) * e > 0]
        if not bundle:
            continue
        x0 = p[bundle, 0]
        xc = float(np.median(x0))
        lane = _pick_lanes([int(out_order[i]) for i in bundle], s, xc, h, x0, clearance, e)
        members = [i for i in bundle if int(out_order[i]) in lane]
        groups = (
            [members]
            if joint
            else [
                [i for i in members if lane[int(out_order[i])] < xc],
                [i for i in members if lane[int(out_order[i])] >= xc],
            ]
        )
        for grp in groups:
            robots = sorted(grp, key=lambda i: (-e * float(p[i, 1]), i))
            ks = sorted(
                (int(out_order[i]) for i in grp),
                key=lambda k: (
                    abs(lane[k] - xc),
                    lane[k],
                    e * float(s[k, 1]) * -1.0,
                    float(s[k, 0]),
                    k,
                ),
            )
            for i, k in _pair(robots, ks, p, s, e):
                out_order[i] = k
                ln, ys = lane[k], float(s[k, 1])
                x_i, y_i = p[i].tolist()
                step = abs(ln - x_i) / LANE_SLOPE
                if step >= e * (ys - y_i) - clearance:  # reaches (or is past) its row
                    continue
                vias[i] = (np.array([ln, y_i + e * step]), np.array([ln, ys]))
                changed = True
    if not changed:
        return None
    return out_order, vias
