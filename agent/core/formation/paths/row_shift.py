"""Row shift: a wide shape laid beside a fleet that stands along its row, so that the
robots walk to it side by side on straight paths (our addition to the placements of
:mod:`agent.core.formation.shape.layout`, for the ``width`` shapes of docs/formation.md
"Shapes" and the ``column``, in the frame :mod:`agent.core.formation.waves.choice` turns
so that the row is x; kept to the safety rule of :mod:`agent.core.formation.waves.safety`
by the scheduler).

Why: a fleet standing in a line, laid on a ``line`` shape centred on it, stretches or
shrinks along the row: every robot walks along the row over the starts and slots of its
neighbours, and under the speed-independent rule they go one after another (each waits
until the one ahead has passed its slot). Moved across the row by D, every path leaves
the row at an angle θ with tan θ >= D / dx (dx the longest walk along the row), and two
robots whose starts are δ apart walk paths about δ·sin θ apart: with

    D = dx · tan(asin(c / δ)),

δ the smallest distance between two starts and c the clearance, neighbouring paths keep
the clearance and the robots walk at once.

The rule (shape frame, x along the row): dx is the longest |x_start − x_slot| of the
given assignment; no shift (None) when δ <= c or dx = 0. The plan of each side (±D, the
min-sum assignment to the moved slots) is one candidate of
:mod:`agent.core.formation.waves.choice`, kept only when its makespan is the smallest.
"""

from __future__ import annotations

import math

import numpy as np

from agent.core.formation.paths.lanes import checked_rows


def row_shift(
    starts_p: np.ndarray, slots_p: np.ndarray, order: np.ndarray, clearance: float
) -> float | None:
    """D of the module doc (m), or None. ``order``: each row's slot (a permutation of the
    rows of ``slots_p``)."""
    p, s, perm = checked_rows(starts_p, slots_p, order, clearance)
    n = p.shape[0]
    if n < 2:
        return None
    dist = np.hypot(p[:, None, 0] - p[None, :, 0], p[:, None, 1] - p[None, :, 1])
    dist[np.arange(n), np.arange(n)] = np.inf
    delta = float(dist.min())
    dx = float(np.max(np.abs(p[:, 0] - s[perm, 0])))
    if delta <= clearance or dx <= 0.0:
        return None
    ratio = clearance / delta
    return dx * ratio / math.sqrt(1.0 - ratio * ratio)
