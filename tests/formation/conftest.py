"""Shared fleets for the formation tests."""

from __future__ import annotations

import numpy as np

from agent.core.formation.frame.records import NeighborRecord


def random_fleet(
    rng: np.random.Generator, n: int, spacing: float = 0.6, spread: float = 1.4
) -> np.ndarray:
    """n positions, pairwise >= spacing apart, in a square scaled with sqrt(n)."""
    side = max(np.sqrt(n) * spacing * spread, spacing)
    pts: list[np.ndarray] = []
    while len(pts) < n:
        p = rng.uniform(0.0, side, 2)
        if all(np.hypot(*(p - q)) >= spacing for q in pts):
            pts.append(p)
    return np.array(pts)


def records_from_positions(
    ids: list[int],
    pos: np.ndarray,
    seen: float = 1.45,
    noise: float = 0.0,
    rng: np.random.Generator | None = None,
) -> list[NeighborRecord]:
    """Ideal (or noisy) records: every robot sees every other within ``seen`` metres."""
    recs = []
    for k, rid in enumerate(ids):
        rel = pos - pos[k]
        d = np.hypot(rel[:, 0], rel[:, 1])
        mask = (d > 0) & (d <= seen)
        nb = rel[mask]
        if noise and rng is not None:
            nb = nb + rng.uniform(-noise, noise, nb.shape)
        recs.append(NeighborRecord(rid, nb))
    return recs
