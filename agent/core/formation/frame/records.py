"""Neighbour records: what each robot shares once (NAO paper 4.1.2).

A record is ``{ID of NAO-i; N_i; (x_ij, y_ij), j in 1..N_i}``: the detections of robot i,
expressed in its *fixed frame* (4.1.1: axes parallel to the world's, origin at robot i),
optionally with the matched mask orientation (3.1.2) and the recognition confidence λ
(Algorithm 1) of each detection.

An addition to the paper's record (docs/design.md §9 "Masks seen mid-turn"): the time
each detection's image was taken (``seen_at``) and the owner's *stances*, the spans over
which its body stood still and at which heading. A robot turns half a circle in its own
search while the others look at it; a mask seen while it turned says nothing of its
start heading, and one seen after it turned says its start heading plus the turn.
:func:`mask_orientation` gives each detection's orientation as if its target stood at
its start heading, or nan when the target was turning (or is not known to have stood
still) when the image was taken.

:func:`canonical_records` is the one ordering every agent uses: records sorted by robot
id, detections inside a record sorted lexicographically by (x, y, orientation,
confidence). :func:`records_digest` hashes that canonical form with bit-exact float64
values, so the digest (and every plan computed from the canonical records) does not
depend on the order in which records or detections arrived.
"""

from __future__ import annotations

import hashlib
import itertools
import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

_DIGEST_TAG = b"nao-formation/records/v1"


@dataclass(frozen=True)
class NeighborRecord:
    """Detections of one robot, in its fixed frame (metres, radians)."""

    robot_id: int
    neighbours: np.ndarray  # (k, 2) float64
    orientations: np.ndarray | None = None  # (k,) rad, matched mask orientation
    confidences: np.ndarray | None = None  # (k,) λ in [0, 1]
    seen_at: np.ndarray | None = None  # (k,) s, the owner's clock at each image
    stances: np.ndarray | None = None  # (s, 3): (from, to, heading) still spans, in order
    clock_error: float = 0.0  # s, how far the owner's clock may be from the fleet's

    def __post_init__(self) -> None:
        rid = self.robot_id
        if isinstance(rid, bool) or not isinstance(rid, int | np.integer) or int(rid) < 0:
            raise ValueError(f"robot_id must be a non-negative int, got {rid!r}")
        object.__setattr__(self, "robot_id", int(rid))
        nb = np.asarray(self.neighbours, dtype=np.float64)
        if nb.size == 0:
            nb = nb.reshape(0, 2)
        if nb.ndim != 2 or nb.shape[1] != 2:
            raise ValueError(
                f"robot {rid}: neighbours must have shape (k, 2), got {np.shape(self.neighbours)}"
            )
        if not np.all(np.isfinite(nb)):
            raise ValueError(f"robot {rid}: neighbours contain non-finite values")
        nb = nb.copy()
        nb.setflags(write=False)
        object.__setattr__(self, "neighbours", nb)
        k = nb.shape[0]
        for name in ("orientations", "confidences", "seen_at"):
            raw = getattr(self, name)
            if raw is None:
                continue
            arr = np.asarray(raw, dtype=np.float64).reshape(-1).copy()
            if arr.shape[0] != k:
                raise ValueError(f"robot {rid}: {arr.shape[0]} {name} for {k} neighbours")
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"robot {rid}: {name} contain non-finite values")
            if name == "confidences" and np.any((arr < 0.0) | (arr > 1.0)):
                raise ValueError(f"robot {rid}: confidences must lie in [0, 1]")
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        if self.stances is not None:
            st = np.asarray(self.stances, dtype=np.float64)
            if st.size == 0:
                st = st.reshape(0, 3)
            if st.ndim != 2 or st.shape[1] != 3:
                raise ValueError(f"robot {rid}: stances must have shape (s, 3), got {st.shape}")
            if not np.all(np.isfinite(st)):
                raise ValueError(f"robot {rid}: stances contain non-finite values")
            bounds = st[:, :2].reshape(-1)
            if np.any(np.diff(bounds) < 0.0):
                raise ValueError(f"robot {rid}: stances must be ordered, non-overlapping spans")
            st = st.copy()
            st.setflags(write=False)
            object.__setattr__(self, "stances", st)
        ce = float(self.clock_error)
        if not (math.isfinite(ce) and ce >= 0.0):
            raise ValueError(f"robot {rid}: clock_error must be finite and >= 0, got {ce!r}")
        object.__setattr__(self, "clock_error", ce)

    @property
    def count(self) -> int:
        return int(self.neighbours.shape[0])


def _sorted_record(rec: NeighborRecord) -> NeighborRecord:
    k = rec.count
    if k <= 1:
        return rec
    ori = rec.orientations if rec.orientations is not None else np.zeros(k)
    conf = rec.confidences if rec.confidences is not None else np.zeros(k)
    # np.lexsort: last key is primary -> x, then y, then orientation, then confidence.
    idx = np.lexsort((conf, ori, rec.neighbours[:, 1], rec.neighbours[:, 0]))
    return NeighborRecord(
        rec.robot_id,
        rec.neighbours[idx],
        None if rec.orientations is None else rec.orientations[idx],
        None if rec.confidences is None else rec.confidences[idx],
        None if rec.seen_at is None else rec.seen_at[idx],
        rec.stances,
        rec.clock_error,
    )


def canonical_records(records: Sequence[NeighborRecord]) -> tuple[NeighborRecord, ...]:
    """Records sorted by robot id, detections sorted; duplicate ids are an error."""
    recs = list(records)
    for r in recs:
        if not isinstance(r, NeighborRecord):
            raise ValueError(f"expected NeighborRecord, got {type(r).__name__}")
    recs.sort(key=lambda r: r.robot_id)
    for a, b in itertools.pairwise(recs):
        if a.robot_id == b.robot_id:
            raise ValueError(f"two records for robot {a.robot_id}")
    return tuple(_sorted_record(r) for r in recs)


def _pack_floats(arr: np.ndarray) -> bytes:
    return np.ascontiguousarray(arr, dtype="<f8").tobytes()


def records_digest(records: Sequence[NeighborRecord]) -> str:
    """sha256 hex of the canonical encoding (order-independent, bit-exact floats)."""
    h = hashlib.sha256(_DIGEST_TAG)
    canon = canonical_records(records)
    h.update(struct.pack("<q", len(canon)))
    for r in canon:
        h.update(struct.pack("<qq", r.robot_id, r.count))
        h.update(_pack_floats(r.neighbours))
        for extra in (r.orientations, r.confidences):
            if extra is None:
                h.update(b"\x00")
            else:
                h.update(b"\x01")
                h.update(_pack_floats(extra))
        if r.seen_at is not None or r.stances is not None:  # absent: the digest of old
            for timed in (r.seen_at, r.stances):
                h.update(b"\x00" if timed is None else b"\x02" + _pack_floats(timed))
            h.update(struct.pack("<d", r.clock_error))
    return h.hexdigest()


def heading_at(stances: np.ndarray | None, t: float, margin: float = 0.0) -> float:
    """The owner's heading (rad, from its start heading) at time ``t`` (s) of another
    clock that may be ``margin`` s from the owner's: that of the stance holding all of
    ``[t - margin, t + margin]``; before the first stance the first's
    (a robot stands still from when it is set down until its search turns it), after the
    last the last's (it stands until it walks, and it walks only on a plan made of every
    record); nan between stances (it was turning). ``stances`` None or empty: 0.0."""
    if stances is None or len(stances) == 0 or not math.isfinite(t):
        return 0.0 if stances is None or len(stances) == 0 else math.nan
    if t <= stances[0, 1] - margin:
        return float(stances[0, 2])
    if t >= stances[-1, 0] + margin:
        return float(stances[-1, 2])
    for t0, t1, h in stances:
        if t0 + margin <= t <= t1 - margin:
            return float(h)
    return math.nan


def mask_view(owner: NeighborRecord, a: int) -> float:
    """Detection ``a`` of ``owner``'s record: its mask orientation θ as the camera read it
    (3.1.2; before any turn-back), nan when the record carries none. What the mask saw of
    its target, front or back, sets how often it reads the target the other way round
    (:meth:`SightingNoise.reversal`)."""
    return math.nan if owner.orientations is None else float(owner.orientations[a])


def mask_orientation(owner: NeighborRecord, a: int, target: NeighborRecord | None) -> float:
    """Detection ``a`` of ``owner``'s record: its mask orientation θ (3.1.2) as if
    ``target`` stood at its start heading, θ − h_target(t_a) (module docstring), in
    (−π, π]; nan when there is none or the target was turning (or may have been, within
    both robots' clock errors). Without times (a record
    that predates them, or ``target`` None) θ as recorded."""
    if owner.orientations is None:
        return math.nan
    theta = float(owner.orientations[a])
    if owner.seen_at is None or target is None or target.stances is None:
        return theta
    margin = owner.clock_error + target.clock_error
    h = heading_at(target.stances, float(owner.seen_at[a]), margin)
    if not math.isfinite(h):
        return math.nan
    return float(math.atan2(math.sin(theta - h), math.cos(theta - h)))


def record_from_polar(
    robot_id: int, distances: Sequence[float], angles: Sequence[float]
) -> NeighborRecord:
    """A record from (d_ij, φ_ij) pairs in the fixed frame (eq. 7 with θ_ij = 0)."""
    d = np.asarray(distances, dtype=np.float64)
    a = np.asarray(angles, dtype=np.float64)
    if d.shape != a.shape:
        raise ValueError("distances and angles must have the same length")
    if np.any(d < 0) or not all(math.isfinite(float(x)) for x in d):
        raise ValueError("distances must be finite and >= 0")
    return NeighborRecord(robot_id, np.stack([d * np.cos(a), d * np.sin(a)], axis=-1))
