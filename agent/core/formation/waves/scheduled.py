"""One assignment to one safe, packed plan: slot swaps until the wave scheduler finds a
safe order (Lemma 1's 2-opt exchange, NAO paper 4.2, applied to pairs that block each
other), then packing, and optionally detours that cut the critical chain.

Pipeline for the robot rows of one assignment: :func:`schedule_with_repair` (the wave
scheduler of :mod:`scheduler`; two robots that block each other in both orders exchange
slots and we schedule again) -> :mod:`detours` (with a bound on the total path, no
obstacles) -> :mod:`packing` (each robot starts once its own conflicts are clear) ->
:class:`Scheduled`, the rows' slot orders, targets, via points, waves and ``after``
lists, with the dependency makespan and the total path by which :mod:`choice` and
:mod:`obstacles` compare candidates.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from agent.core.formation.params import PlanParams
from agent.core.formation.waves.detours import shorten
from agent.core.formation.waves.packing import pack, regroup_waves
from agent.core.formation.waves.safety import pair_flags
from agent.core.formation.waves.scheduler import Schedule, ScheduleError, schedule

#: How many rounds of slot swaps :func:`schedule_with_repair` may make before giving up.
MAX_SWAPS = 10


def schedule_with_repair(
    pos: np.ndarray,
    targets: np.ndarray,
    order: np.ndarray,
    vias: list[tuple[np.ndarray, ...]],
    obs: np.ndarray,
    params: PlanParams,
) -> tuple[Schedule, np.ndarray, np.ndarray]:
    """Schedule; when two robots block each other in both orders (each one's slot lies
    within the clearance of the other's start: a swap no single wave can do), they
    exchange slots (a 2-opt step in the spirit of Lemma 1) and we schedule again, keeping
    the detours found for the other robots. Blocked pairs are swapped in ascending row
    order, each robot at most once per round."""
    order = order.copy()
    targets = np.array(targets, dtype=np.float64)
    vias = list(vias)
    prior: ScheduleError | None = None
    for _ in range(MAX_SWAPS + 1):
        leader_row = int(np.flatnonzero(order == 0)[0])
        try:
            sched = schedule(
                pos,
                targets,
                leader_row,
                order,
                params.radius,
                fixed_vias=vias,
                obstacles=obs,
                prior=prior,
            )
            return sched, order, targets
        except ScheduleError as exc:
            if not exc.pairs:
                raise
            prior = exc
            if exc.vias:
                vias = list(exc.vias)
            touched: set[int] = set()
            for a, b in sorted(exc.pairs):
                if a in touched or b in touched:
                    continue
                touched.update((a, b))
                order[[a, b]] = order[[b, a]]
                targets[[a, b]] = targets[[b, a]]
                vias[a], vias[b] = (), ()
    raise ValueError(f"no safe schedule found after {MAX_SWAPS} rounds of slot swaps")


def _path(start: np.ndarray, via: Sequence[np.ndarray], target: np.ndarray) -> np.ndarray:
    return np.vstack([start, *via, target])


def path_length(start: np.ndarray, via: Sequence[np.ndarray], target: np.ndarray) -> float:
    """Length of the polyline start -> via... -> target."""
    p = _path(start, via, target)
    return float(np.sum(np.hypot(*np.diff(p, axis=0).T)))


@dataclass(frozen=True)
class Scheduled:
    """A safe plan for robot rows: slot orders, targets, via points, waves, after lists."""

    order: np.ndarray
    targets: np.ndarray
    vias: tuple[tuple[np.ndarray, ...], ...]
    waves: np.ndarray
    after: tuple[tuple[int, ...], ...]
    strategy: str
    #: per robot, per ``after`` entry: how far that robot must have walked (release)
    after_at: tuple[tuple[float, ...], ...] = ()
    makespan: float = 0.0  # dependency makespan (path-length units)
    total: float = 0.0  # total path length


def scheduled_plan(
    pos: np.ndarray,
    targets: np.ndarray,
    order: np.ndarray,
    vias: Sequence[tuple[np.ndarray, ...]],
    obs: np.ndarray,
    params: PlanParams,
    strategy: str,
    bound: float | None = None,
) -> Scheduled:
    """Schedule (slot swaps and detours until safe, see :func:`schedule_with_repair`),
    then pack the waves (:mod:`packing`); with a ``bound`` on the total path (no
    obstacles), first shorten the critical chain by detours (:mod:`detours`). Raises
    ``ValueError`` if no schedule is found."""
    sched, order, targets = schedule_with_repair(pos, targets, order, list(vias), obs, params)
    n = pos.shape[0]
    flags = sched.flags
    vias_rows = sched.vias
    if flags is None:  # pragma: no cover - schedule() always returns its flags
        paths = [_path(pos[k], vias_rows[k], targets[k]) for k in range(n)]
        flags = pair_flags(paths, 2.0 * params.radius)
    leader_row = int(np.flatnonzero(order == 0)[0])
    if bound is not None and not obs.shape[0]:
        for wide in (False, True):  # the narrow search, then the wide one from its result
            targets, order, vias_rows, flags = shorten(
                pos, targets, vias_rows, flags, order, params.radius, bound, wide=wide
            )
        leader_row = int(np.flatnonzero(order == 0)[0])
    lengths = np.array(
        [path_length(pos[k], vias_rows[k], targets[k]) for k in range(n)], dtype=np.float64
    )
    start, after, waves, release = pack(flags, lengths, leader_row, order)
    waves = regroup_waves(lengths, after, waves, leader_row)
    return Scheduled(
        order,
        targets,
        vias_rows,
        waves,
        after,
        strategy,
        after_at=release,
        makespan=float(np.max(start + lengths)),
        total=float(lengths.sum()),
    )
