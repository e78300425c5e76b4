"""Which scheduled plan, without obstacles: the ``default`` strategy's comparison of
candidate assignments, or the attempts of :meth:`params.PlanParams.attempts` in turn.

Candidates (n <= ``CANDIDATES_MAX_N``): the min-sum assignment (``optimal``), min-sum
under bounds on the longest path between B* and min-sum's own (the CAT-ORA idea), and
CAPT, all on the centred slots of the shape (the pyramid: AUV eqs. 5-7). Each is made
safe and packed (:mod:`scheduled`); of those whose total path stays within
``PATH_SLACK`` of the optimum, the best by dependency makespan get detours on their
critical chain, a copy with start sidesteps (:mod:`kinks`) and two copies with bundle
lanes (:mod:`lanes`: the slots of each bundle re-paired per side and jointly, from the
detoured plan's assignment; a shape with a single slot column has none), and the
smallest makespan wins; a lane plan only when its makespan is
strictly smaller than every other. A shape whose row lies along the fleet (a ``width``
shape, or a ``depth`` shape of one slot column: the ``column``) also gets side-by-side
candidates (:func:`_row_plans`): row lanes (:mod:`row_lanes`) and the
slots moved across the row (:mod:`row_shift`): extra candidates (every other one is
made as without them), those among the best SHORTENED of all by makespan get detours.
Otherwise each placement in turn gets the paper's matching (NAO paper 4.2, Lemma 1) or
the explicit strategy, until one schedules safely.
"""

from __future__ import annotations

import math

import numpy as np

from agent.core.formation.params import CANDIDATES_MAX_N, PlanParams
from agent.core.formation.paths.assignment import assign, bounded_assignment, min_bottleneck
from agent.core.formation.paths.kinks import start_kinks
from agent.core.formation.paths.lanes import bundle_lanes
from agent.core.formation.paths.row_lanes import row_lanes
from agent.core.formation.paths.row_shift import row_shift
from agent.core.formation.shape.layout import column_step, placed
from agent.core.formation.shape.pyramid import PyramidFrame
from agent.core.formation.waves.scheduled import Scheduled, scheduled_plan

#: The ``default`` strategy keeps a plan whose total path is at most this many times the
#: smallest total (the min-sum assignment's straight paths).
PATH_SLACK = 1.05

#: Bounds on the longest path the ``default`` strategy tries (n <= CANDIDATES_MAX_N), as
#: fractions of the way from B* (the smallest possible longest path) to the longest path
#: of the min-sum assignment.
BOUND_STEPS = (0.0, 0.25, 0.5, 0.75)

#: How many of the best candidates (by makespan before detours) get detours.
SHORTENED = 3

#: A bundle-lane plan (:mod:`lanes`) replaces the best plan only when its makespan is
#: smaller by more than this (path-length units: rounding).
LANES_MARGIN = 1e-9

#: A row-lane plan (:mod:`row_lanes`) may walk up to this many times the smallest total
#: (its lanes lie beside the row: the price of walking side by side).
ROW_LANES_SLACK = 1.25

#: Row-lane and row-shift plans rank after every other plan of equal makespan and total.
ROW_RANK = 1000

_NO_OBS = np.zeros((0, 2))


def _row_plans(
    pos: np.ndarray,
    frame: PyramidFrame,
    starts_p: np.ndarray,
    slots_p: np.ndarray,
    orders: list[tuple[str, np.ndarray]],
    params: PlanParams,
    bound: float,
    along: int = 0,
) -> list[tuple[float, float, int, Scheduled, float]]:
    """(makespan, total, rank, plan, bound on its total) of the side-by-side plans of a
    shape whose row lies along the fleet (its x axis, ``along=0``: a ``width`` shape;
    its y axis, ``along=1``: a ``depth`` shape of one slot column): the row-lane plans
    (:mod:`row_lanes`) of each given (strategy, slot order), kept and re-paired, with a
    total path <= ``bound``; then the straight min-sum plans to the slots moved across
    the row either way (:mod:`row_shift`), whose bound is PATH_SLACK × their own
    straight total. Ranks from ROW_RANK in that order; duplicates dropped; plans that
    cannot be scheduled left out."""
    out: list[tuple[float, float, int, Scheduled, float]] = []
    seen: set[bytes] = set()
    clear = 2.0 * params.radius
    k = [1, 0] if along else [0, 1]  # the row's frame: x along the row (a swap for y)
    rs, rt = starts_p[:, k], slots_p[:, k]
    for strat, perm in orders:
        for repair in (False, True):
            got = row_lanes(rs, rt, perm, clear, repair)
            if got is None or got[0].tobytes() in seen:
                continue
            seen.add(got[0].tobytes())
            order, vias = got
            try:
                sc = scheduled_plan(
                    pos,
                    frame.to_common(slots_p[order]),
                    order,
                    [tuple(frame.to_common(v[k]) for v in vs) for vs in vias],
                    _NO_OBS,
                    params,
                    strat,
                )
            except ValueError:
                continue
            if sc.total <= bound:
                out.append((sc.makespan, sc.total, ROW_RANK + len(out), sc, bound))
    opt = assign(starts_p, slots_p, "optimal", params.d_e, params.phi_e)
    shift = row_shift(rs, rt, opt, clear)
    for sign in (1.0, -1.0) if shift is not None else ():
        moved = slots_p + np.array([0.0, sign * float(shift or 0.0)])[k]
        perm = assign(starts_p, moved, "optimal", params.d_e, params.phi_e)
        empty: list[tuple[np.ndarray, ...]] = [() for _ in range(pos.shape[0])]
        try:
            sc = scheduled_plan(
                pos, frame.to_common(moved[perm]), perm, empty, _NO_OBS, params, "optimal"
            )
        except ValueError:
            continue
        own = _slack_bound(starts_p, moved, perm)
        if sc.total <= own:
            out.append((sc.makespan, sc.total, ROW_RANK + len(out), sc, own))
    return out


def _candidates(starts_p: np.ndarray, slots_p: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """Assignments the ``default`` strategy compares: min-sum first, then min-sum under
    bounds on the longest path between B* and min-sum's own (CAT-ORA's idea), then CAPT.
    Duplicates are dropped (first kept)."""
    opt = assign(starts_p, slots_p, "optimal", 1.0, 0.5)
    longest = float(np.max(np.hypot(*(starts_p - slots_p[opt]).T)))
    b_star = min_bottleneck(starts_p, slots_p)
    out = [("optimal", opt)]
    for f in BOUND_STEPS:
        out.append(
            ("bottleneck", bounded_assignment(starts_p, slots_p, b_star + f * (longest - b_star)))
        )
    out.append(("capt", assign(starts_p, slots_p, "capt", 1.0, 0.5)))
    seen: set[bytes] = set()
    uniq = []
    for name, perm in out:
        key = perm.tobytes()
        if key not in seen:
            seen.add(key)
            uniq.append((name, perm))
    return uniq


def _slack_bound(starts_p: np.ndarray, slots_p: np.ndarray, perm: np.ndarray) -> float:
    """PATH_SLACK × the total of the straight paths of the assignment ``perm``."""
    straight = np.hypot(*(starts_p - slots_p[perm]).T)
    return PATH_SLACK * float(straight.sum()) + 1e-9


def _scheduled(
    pos: np.ndarray,
    frame: PyramidFrame,
    starts_p: np.ndarray,
    slots_p: np.ndarray,
    candidates: list[tuple[str, np.ndarray]],
    obs: np.ndarray,
    params: PlanParams,
    slack: bool = True,
) -> tuple[list[tuple[float, float, int, Scheduled]], float]:
    """Each candidate assignment made safe and packed; those whose total path is within
    ``PATH_SLACK`` of the first candidate's straight paths (min-sum's; every one without
    ``slack``), as (makespan, total, candidate index, plan) sorted, and that bound."""
    empty: list[tuple[np.ndarray, ...]] = [() for _ in range(pos.shape[0])]
    good: list[tuple[float, float, int, Scheduled]] = []
    bound = math.inf
    for k, (strat, perm) in enumerate(candidates):
        if k == 0 and slack:
            bound = _slack_bound(starts_p, slots_p, perm)
        try:
            sc = scheduled_plan(
                pos, frame.to_common(slots_p[perm]), perm, empty, obs, params, strat
            )
        except ValueError:
            continue
        if sc.total <= bound:
            good.append((sc.makespan, sc.total, k, sc))
    good.sort(key=lambda g: g[:3])
    return good, bound


def choose_anchored(
    pos: np.ndarray, frame: PyramidFrame, row: int, obs: np.ndarray, params: PlanParams
) -> Scheduled | None:
    """The plan that lays the shape's slot 0 on the robot of ``row``, which stays where it
    stands: ``frame``'s origin is that robot's start (the circle pattern's centre robot and
    its leader, AUV III.B.2.a). The others take the rest of the slots by the
    :func:`_candidates` assignments on them, made safe and packed (``obs``: obstacles,
    (M, 2), common frame), those that keep the anchor in place; of those within the
    path slack (every one when none is: a robot that must walk round the anchor), the
    best by makespan, then total path, gets detours on its critical chain. No start
    sidesteps, lanes or other placements: they would move the anchor or the slots.
    None: a slot within two radii of an obstacle, or no candidate schedules with the
    anchor in place."""
    n = pos.shape[0]
    if not 0 <= row < n:
        raise ValueError(f"anchor row must be in [0, {n}), got {row}")
    starts_p = frame.to_pyramid(pos)
    slots_p = params.shape.slots(n, params.d_e, params.phi_e).positions  # slot 0 at (0, 0)
    if obs.shape[0]:  # a slot on an obstacle: no plan holds it
        slots_c = frame.to_common(slots_p)
        gap = np.hypot(*(slots_c[:, None, :] - obs[None, :, :]).transpose(2, 0, 1))
        if float(gap.min()) < 2.0 * params.radius:
            return None
    rest = np.flatnonzero(np.arange(n) != row)
    cands = []
    subs = _candidates(starts_p[rest], slots_p[1:]) if n > 1 else [("optimal", rest)]
    for strat, sub in subs:
        perm = np.zeros(n, dtype=np.int64)
        perm[rest] = np.asarray(sub, dtype=np.int64) + 1
        cands.append((strat, perm))
    every, _ = _scheduled(pos, frame, starts_p, slots_p, cands, obs, params, slack=False)
    # the anchor in place (a slot swap of the repair may move it: that plan is dropped)
    good = [g for g in every if g[3].order[row] == 0 and not g[3].vias[row]]
    if not good:
        return None
    bound = _slack_bound(starts_p, slots_p, cands[0][1])
    within = [g for g in good if g[1] <= bound]
    best = min(within or good, key=lambda g: g[:3])[3]
    if within and not obs.shape[0]:  # detours on the critical chain, if the anchor stays
        empty: list[tuple[np.ndarray, ...]] = [() for _ in range(n)]
        better = scheduled_plan(
            pos, best.targets, best.order, empty, obs, params, best.strategy, bound=bound
        )
        if better.order[row] == 0 and not better.vias[row]:
            return better
    return best


def choose(
    pos: np.ndarray, frame: PyramidFrame, starts_p: np.ndarray, params: PlanParams
) -> Scheduled | None:
    """The scheduled plan of the first attempt that succeeds (see PlanParams.attempts).

    ``default`` with n <= CANDIDATES_MAX_N first compares the :func:`_candidates` assignments on the
    centred pyramid: of those that schedule with a total path <= PATH_SLACK × the
    min-sum total, the smallest dependency makespan wins (then the smaller total, then
    the order of CANDIDATES). None: no attempt could be scheduled.
    """
    n = pos.shape[0]
    empty: list[tuple[np.ndarray, ...]] = [() for _ in range(n)]
    exact = params.strategy == "default" and params.placement in ("default", "centroid")
    if exact and n <= CANDIDATES_MAX_N:
        slots_p = placed(params.shape, n, params.d_e, params.phi_e, starts_p, "centroid")
        step = column_step(params.shape, slots_p[:, 0], params.d_e, params.phi_e)
        good, bound = _scheduled(
            pos, frame, starts_p, slots_p, _candidates(starts_p, slots_p), _NO_OBS, params
        )
        # side by side (a wide shape's row lanes and shifts): extra candidates; those that
        # rank among the best SHORTENED of all by makespan get detours
        along = 0 if params.shape.orient == "width" else 1 if not math.isfinite(step) else -1
        rowed = _row_plans(
            pos, frame, starts_p, slots_p, [(g[3].strategy, g[3].order) for g in good], params,
            (bound - 1e-9) / PATH_SLACK * ROW_LANES_SLACK + 1e-9, along,
        ) if along >= 0 else []  # fmt: skip
        best = [g[3] for g in sorted(good + [r[:4] for r in rowed], key=lambda g: g[:3])]
        best = best[:SHORTENED]
        for j, (_, _, k, sc, own) in enumerate(rowed):
            if any(sc is b for b in best):
                sc = scheduled_plan(
                    pos, sc.targets, sc.order, sc.vias, _NO_OBS, params, sc.strategy, bound=own
                )
                rowed[j] = (sc.makespan, sc.total, k, sc, own)
        axis = np.array([math.cos(frame.beta), math.sin(frame.beta)])
        kinked: list[tuple[float, float, int, Scheduled]] = []
        laned: list[tuple[float, float, int, Scheduled]] = []
        clear = 2.0 * params.radius
        for j, (_, _, k, sc) in enumerate(good[:SHORTENED]):  # detours for the best
            better = scheduled_plan(
                pos, sc.targets, sc.order, empty, _NO_OBS, params, sc.strategy, bound=bound
            )
            good[j] = (better.makespan, better.total, k, better)
            # the same with start sidesteps (kinks), ranked after every plan without
            vias = start_kinks(pos, sc.targets, axis, clear)
            alt = None
            if any(vias):
                try:
                    alt = scheduled_plan(
                        pos, sc.targets, sc.order, vias, _NO_OBS, params, sc.strategy, bound=bound
                    )
                except ValueError:
                    alt = None
            if alt is not None and alt.total <= bound:
                kinked.append((alt.makespan, alt.total, len(BOUND_STEPS) + 2 + k, alt))
            # the same with bundle lanes (a lane each, slots re-paired in the bundle)
            for m, joint in enumerate((False, True) if math.isfinite(step) else ()):
                ln = bundle_lanes(
                    starts_p, slots_p, better.order, params.d_e, params.phi_e, clear, joint, step
                )
                if ln is None:
                    continue
                lanes_order, lanes_vias = ln
                try:
                    alt = scheduled_plan(
                        pos,
                        frame.to_common(slots_p[lanes_order]),
                        lanes_order,
                        [tuple(frame.to_common(v) for v in vs) for vs in lanes_vias],
                        _NO_OBS,
                        params,
                        sc.strategy,
                        bound=bound,
                    )
                except ValueError:
                    continue
                if alt.total <= bound:
                    laned.append((alt.makespan, alt.total, 2 * k + m, alt))
        good += kinked + [r[:4] for r in rowed]
        if good:
            win = min(good, key=lambda g: g[:3])
            if laned:  # kept only when its makespan is strictly smaller
                lane_win = min(laned, key=lambda g: g[:3])
                if lane_win[0] < win[0] - LANES_MARGIN:
                    win = lane_win
            return win[3]
    for strat, placement in params.attempts(n):
        slots_p = placed(params.shape, n, params.d_e, params.phi_e, starts_p, placement)
        perm = assign(starts_p, slots_p, strat, params.d_e, params.phi_e)
        try:
            return scheduled_plan(
                pos, frame.to_common(slots_p[perm]), perm, empty, _NO_OBS, params, strat
            )
        except ValueError:
            continue
    return None
