"""The search's half turn measured where the two sweeps' views overlap (an addition to
NAO paper 5.2.2 (iii) step 2; the visual compass of 3.2.1, eq. 2).

The search sweeps the head at θ = 0, turns the body by π with the rotation control and
sweeps again. With the head's ±119.5° range the two sweeps look the same ways at their
ends: the head at +119.5° after the half turn looks where the head at -60.5° looked
before it. The visual compass between two such views measures the angle between them,
and since both the head yaws are known, the body's turn is

    turn = (yaw_before - yaw_after) + compass(view_before, view_after)   (mod 2π),

unwrapped next to the rotation control's own sum. That is the absolute turn over the
half circle: the compass's scale error (parallax of the off-axis camera, a few per cent
per step) does not accumulate into it. Before this, the robot completed the circle to
θ = 0 and compared its first and last images (13 more compass images and turns); the
overlapping views give the same absolute reference with none.

:func:`overlap_pairs` chooses the pairs of views (pure geometry of the yaws);
:func:`half_turn` combines the pairs' measurements, or returns ``None`` when fewer than
:data:`MIN_AGREEING` agree: the caller then completes the circle as before.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

#: Largest angle between the views of a pair (rad): the compass matches 15° body
#: steps; two views 6° apart share most of the image.
MAX_PAIR_OFFSET = math.radians(10.0)
#: Measurements within this angle (rad) of the median agree with it.
AGREE = math.radians(0.5)
#: Fewer agreeing measurements than this, and the half turn is not measured.
MIN_AGREEING = 2


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def overlap_pairs(
    yaws: Sequence[float], turn: float = math.pi, max_offset: float = MAX_PAIR_OFFSET
) -> tuple[tuple[int, int], ...]:
    """Pairs ``(i, j)``: the view at head yaw ``yaws[i]`` before a body turn of ``turn``
    and the view at ``yaws[j]`` after it look within ``max_offset`` of the same way.

    Each after-view ``j`` (ascending) takes the before-view nearest its direction; ties
    go to the smaller index. With the search's ten yaws over ±119.5°: six pairs, each
    5.9° apart.

    Raises ``ValueError`` on a non-finite yaw, turn or offset, or an offset outside
    (0, π/4].
    """
    ys = [float(y) for y in yaws]
    if not all(math.isfinite(v) for v in (*ys, turn, max_offset)):
        raise ValueError("yaws, turn and max_offset must be finite")
    if not 0.0 < max_offset <= math.pi / 4:
        raise ValueError(f"max_offset must be in (0, pi/4], got {max_offset}")
    pairs: list[tuple[int, int]] = []
    for j, after in enumerate(ys):
        gaps = [abs(_wrap(turn + after - before)) for before in ys]
        i = int(np.argmin(gaps))  # the first of equal gaps
        if gaps[i] <= max_offset:
            pairs.append((i, j))
    return tuple(pairs)


def half_turn(
    measurements: Sequence[tuple[float, float, float]],
    turned: float,
    agree: float = AGREE,
    min_agreeing: int = MIN_AGREEING,
) -> float | None:
    """The body's turn (rad) between the sweeps from the overlapping views' compass.

    ``measurements``: ``(yaw_before, yaw_after, compass)`` for every pair the compass
    matched, ``compass`` being the view's rotation from the before-view to the
    after-view (rad, + CCW). Each gives the turn ``yaw_before - yaw_after + compass``,
    unwrapped to within π of ``turned`` (the rotation control's sum). The result is the
    median of those estimates, provided at least ``min_agreeing`` of them lie within
    ``agree`` of it; otherwise ``None``.

    Raises ``ValueError`` on a non-finite input, ``agree`` <= 0 or ``min_agreeing`` < 1.
    """
    if not math.isfinite(turned) or not (agree > 0 and math.isfinite(agree)):
        raise ValueError("turned must be finite and agree finite and > 0")
    if min_agreeing < 1:
        raise ValueError(f"min_agreeing must be >= 1, got {min_agreeing}")
    est: list[float] = []
    for before, after, compass in measurements:
        if not all(math.isfinite(v) for v in (before, after, compass)):
            raise ValueError(f"measurement {(before, after, compass)} is not finite")
        est.append(turned + _wrap(before - after + compass - turned))
    if len(est) < min_agreeing:
        return None
    med = float(np.median(est))
    if sum(abs(e - med) <= agree for e in est) < min_agreeing:
        return None
    return med
