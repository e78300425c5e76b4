"""Fleets with unaligned start poses, their records, and record faults (docs/design.md §9).

A robot's start pose is (x, y, h) in the world, h its body heading; its fixed frame is
its start pose with the body facing +y (π/2), so ψ = h − π/2 and a world vector w reads
``R(−ψ) w`` in it. Mask orientations follow the M-base convention (the observed body
heading minus the line of sight), with the observed robot at θ = 0 or 180° of its
search (random) and quantised to the masks' 5° when noisy (``rng`` given).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from agent.core.formation.frame.records import NeighborRecord
from agent.core.perception.sighting_noise import SightingNoise
from tests.formation.conftest import random_fleet

MASK_STEP = math.radians(5.0)
#: A timed record's stances: stood at its start heading until 1 s, half turned round
#: from 2 s (its search); and when a mask of it was seen, before or after its turn
STANCES = np.array([[0.0, 1.0, 0.0], [2.0, 3.0, math.pi]])
SEEN_AT = (0.5, 2.5)


def rot(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s], [s, c]])


def sim_layout(rng: np.random.Generator, n: int) -> np.ndarray:
    """Positions (n, 2) like the simulator's: 0.6-2.5 m to the nearest neighbour, every
    robot within 3.0 m of at least two others (one other for n = 2)."""
    side = 1.2 * math.sqrt(n)
    while True:
        pts: list[np.ndarray] = []
        tries = 0
        while len(pts) < n and tries < 1000:
            tries += 1
            p = rng.uniform(0.0, side, 2)
            if all(np.hypot(*(p - q)) >= 0.6 for q in pts):
                pts.append(p)
        if len(pts) < n:
            continue
        pos = np.array(pts)
        d = np.hypot(*(pos[:, None, :] - pos[None, :, :]).transpose(2, 0, 1))
        np.fill_diagonal(d, np.inf)
        seen = ((d >= 0.5) & (d <= 3.0)).sum(axis=1)
        if d.min(axis=1).max() <= 2.5 and seen.min() >= min(2, n - 1):
            return pos


def unaligned_records(
    ids: list[int],
    pos: np.ndarray,
    headings: np.ndarray,
    rng: np.random.Generator | None = None,
    dist_noise: float = 0.0,
    bearing_noise: float = 0.0,
    masks: bool = True,
    reach: tuple[float, float] = (0.5, 3.0),
    timed: bool = False,
) -> list[NeighborRecord]:
    """Records of robots at world ``pos`` with body headings ``headings`` (rad);
    ``timed``: with times, as today's agents send them (:data:`STANCES`: every robot
    stood at its start heading, then half turned round in its search; each mask seen
    before or after its target's turn, as its orientation says)."""
    recs = []
    for k, rid in enumerate(ids):
        psi = headings[k] - math.pi / 2
        nb, ori, seen = [], [], []
        for j in range(len(ids)):
            w = pos[j] - pos[k]
            d = math.hypot(*w)
            if j == k or not reach[0] <= d <= reach[1]:
                continue
            los = math.atan2(w[1], w[0])
            b = los - psi
            if rng is not None:
                d *= 1.0 + rng.uniform(-dist_noise, dist_noise)
                b += rng.uniform(-bearing_noise, bearing_noise)
            nb.append([d * math.cos(b), d * math.sin(b)])
            turned = math.pi if (rng is not None and rng.random() < 0.5) else 0.0
            seen.append(SEEN_AT[turned > 0.0])
            theta = (headings[j] + turned - los) % (2 * math.pi)
            if rng is not None:
                theta += rng.uniform(-bearing_noise, bearing_noise)
                theta = MASK_STEP * round(theta / MASK_STEP)  # the masks' 5° steps
            ori.append(theta % (2 * math.pi))
        arr = np.array(nb, dtype=np.float64).reshape(-1, 2)
        rec = NeighborRecord(rid, arr, np.array(ori) if masks and nb else None)
        if timed:
            rec = replace(rec, seen_at=np.array(seen, dtype=np.float64), stances=STANCES)
        recs.append(rec)
    return recs


def fault(rec: NeighborRecord, kind: str) -> NeighborRecord:
    """``rotate`` 40° (a compass off), ``scale`` 1.4 (a D-base off), ``shift`` 0.5 m (a liar)."""
    nb = rec.neighbours
    if kind == "rotate":
        nb = nb @ rot(math.radians(40.0)).T
    elif kind == "scale":
        nb = nb * 1.4
    elif kind == "shift":
        nb = nb + np.array([0.5, 0.0])
    else:
        raise ValueError(kind)
    return NeighborRecord(rec.robot_id, nb, rec.orientations, rec.confidences)


#: A dense room's spread (tests.formation.conftest.random_fleet): a square of side
#: 0.8·√n m, robots ≥ 0.6 m apart (median nearest neighbour ~0.7 m, as the 50- and
#: 100-NAO runs).
DENSE_SPREAD = 0.8 / 0.6


#: The noise model of :func:`dense_records` (4 % of the distance, 2° across; the fleet's
#: fault test must be told the noise of the records it judges, not the rendered one's).
DENSE_NOISE = SightingNoise.synthetic(0.005, 0.04, math.radians(2.0))


def dense_records(
    rng: np.random.Generator, n: int, headings: np.ndarray | None = None, keep: float = 0.7
) -> tuple[np.ndarray, np.ndarray, list[NeighborRecord]]:
    """A dense room's records: every robot within 3.5 m seen with 4 % distance and 2°
    bearing noise, each sighting then kept with probability ``keep`` on each side (the
    occluded ones missed: many sightings one-way). Returns (positions, headings, records)."""
    pos = random_fleet(rng, n, spacing=0.6, spread=DENSE_SPREAD)
    h = np.full(n, math.pi / 2) if headings is None else headings
    ids = list(range(1, n + 1))
    recs = unaligned_records(ids, pos, h, rng, 0.04, math.radians(2.0), True, (0.5, 3.5))
    out = []
    for r in recs:
        m = rng.random(r.count) < keep
        ori = None if r.orientations is None else r.orientations[m]
        out.append(NeighborRecord(r.robot_id, r.neighbours[m], ori))
    return pos, h, out


def masks_turned(
    recs: list[NeighborRecord], pos: np.ndarray, headings: np.ndarray, robot: int, deg: float
) -> list[NeighborRecord]:
    """``recs`` with every mask of ``robot`` (id; ids 1..n at ``pos``) turned by ``deg``:
    the others saw its body turned while it turned through its own search; its start pose
    and its own sightings are unchanged."""
    out = []
    for rec in recs:
        ori = rec.orientations
        if ori is not None and rec.robot_id != robot:
            own = pos[rec.robot_id - 1]
            world = rec.neighbours @ rot(headings[rec.robot_id - 1] - math.pi / 2).T + own
            on = np.hypot(*(world - pos[robot - 1]).T) < 0.25
            ori = np.where(on, (ori + math.radians(deg)) % (2 * math.pi), ori)
        out.append(NeighborRecord(rec.robot_id, rec.neighbours, ori, rec.confidences))
    return out
