"""Neighbour records: what each robot shares once (NAO paper 4.1.2).

A record is ``{ID of NAO-i; N_i; (x_ij, y_ij), j in 1..N_i}``: the detections of robot i,
expressed in its *fixed frame* (4.1.1: axes parallel to the world's, origin at robot i),
optionally with the matched mask orientation (3.1.2) and the recognition confidence λ
(Algorithm 1) of each detection.

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
        for name in ("orientations", "confidences"):
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
    return h.hexdigest()


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
