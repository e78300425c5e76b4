"""Records and their digest (NAO paper 4.1.2)."""

from __future__ import annotations

import numpy as np
import pytest

from agent.core.formation.frame.records import (
    NeighborRecord,
    canonical_records,
    record_from_polar,
    records_digest,
)


def _recs() -> list[NeighborRecord]:
    return [
        NeighborRecord(
            2, np.array([[0.5, 1.0], [-0.7, 0.2]]), np.array([0.1, 3.0]), np.array([0.9, 0.7])
        ),
        NeighborRecord(0, np.array([[0.3, -0.4]])),
        NeighborRecord(5, np.zeros((0, 2))),
    ]


def test_digest_independent_of_record_and_detection_order() -> None:
    recs = _recs()
    d = records_digest(recs)
    assert d == records_digest(list(reversed(recs)))
    r2 = recs[0]
    flipped = NeighborRecord(2, r2.neighbours[::-1], r2.orientations[::-1], r2.confidences[::-1])  # type: ignore[index]
    assert records_digest([flipped, recs[1], recs[2]]) == d
    assert len(d) == 64


def test_digest_changes_with_one_bit() -> None:
    recs = _recs()
    nb = recs[1].neighbours.copy()
    nb[0, 0] = np.nextafter(nb[0, 0], 1.0)
    assert records_digest([recs[0], NeighborRecord(0, nb), recs[2]]) != records_digest(recs)
    # absent vs present optional arrays differ too
    assert records_digest([NeighborRecord(0, nb, confidences=np.array([1.0]))]) != records_digest(
        [NeighborRecord(0, nb)]
    )


def test_canonical_sorts_and_rejects_duplicates() -> None:
    canon = canonical_records(_recs())
    assert [r.robot_id for r in canon] == [0, 2, 5]
    assert canon[1].neighbours[0, 0] == -0.7
    with pytest.raises(ValueError, match="two records for robot 0"):
        canonical_records(
            [NeighborRecord(0, np.zeros((0, 2))), NeighborRecord(0, np.zeros((0, 2)))]
        )
    with pytest.raises(ValueError, match="expected NeighborRecord"):
        canonical_records(["x"])  # type: ignore[list-item]


@pytest.mark.parametrize(
    ("kwargs", "msg"),
    [
        ({"robot_id": -1, "neighbours": np.zeros((0, 2))}, "non-negative"),
        ({"robot_id": True, "neighbours": np.zeros((0, 2))}, "non-negative"),
        ({"robot_id": 1, "neighbours": np.zeros((2, 3))}, "shape"),
        ({"robot_id": 1, "neighbours": np.array([[np.nan, 0.0]])}, "non-finite"),
        (
            {"robot_id": 1, "neighbours": np.zeros((2, 2)), "orientations": np.zeros(3)},
            "3 orientations",
        ),
        (
            {"robot_id": 1, "neighbours": np.zeros((1, 2)), "confidences": np.array([1.5])},
            r"\[0, 1\]",
        ),
        (
            {"robot_id": 1, "neighbours": np.zeros((1, 2)), "confidences": np.array([np.inf])},
            "non-finite",
        ),
    ],
)
def test_record_errors(kwargs: dict, msg: str) -> None:
    with pytest.raises(ValueError, match=msg):
        NeighborRecord(**kwargs)


def test_record_from_polar() -> None:
    r = record_from_polar(3, [1.0, 2.0], [0.0, np.pi / 2])
    assert np.allclose(r.neighbours, [[1.0, 0.0], [0.0, 2.0]])
    with pytest.raises(ValueError, match="same length"):
        record_from_polar(3, [1.0], [0.0, 1.0])
    with pytest.raises(ValueError, match=">= 0"):
        record_from_polar(3, [-1.0], [0.0])
