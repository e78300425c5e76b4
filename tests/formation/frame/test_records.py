"""Records and their digest (NAO paper 4.1.2)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from agent.core.formation.frame.records import (
    NeighborRecord,
    canonical_records,
    heading_at,
    mask_orientation,
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


# --- times: when each sighting was seen, and the owner's stances -------------------------

#: the digest of _recs() before records carried times (computed on the code of that time)
DIGEST_WITHOUT_TIMES = "776c3818b4751eaf02a368ddef956852da6fe0c53284629ad1cbae669af96980"
STANCES = np.array([[1.0, 4.0, 0.0], [7.0, 9.0, math.pi], [12.0, 12.0, 0.5]])


def test_records_without_times_keep_their_digest() -> None:
    assert records_digest(_recs()) == DIGEST_WITHOUT_TIMES


def test_times_enter_the_digest_and_follow_their_detection() -> None:
    base = _recs()[0]
    timed = NeighborRecord(2, base.neighbours, base.orientations, base.confidences,
                           np.array([3.0, 8.0]), STANCES)  # fmt: skip
    other = NeighborRecord(2, base.neighbours, base.orientations, base.confidences,
                           np.array([8.0, 3.0]), STANCES)  # fmt: skip
    digests = {records_digest([r]) for r in (base, timed, other)}
    assert len(digests) == 3
    flipped = NeighborRecord(2, base.neighbours[::-1], base.orientations[::-1],  # type: ignore[index]
                             base.confidences[::-1], np.array([8.0, 3.0]), STANCES)  # type: ignore[index]  # fmt: skip
    assert records_digest([flipped]) == records_digest([timed])
    canon = canonical_records([flipped])[0]
    assert canon.seen_at is not None
    assert dict(zip(canon.orientations, canon.seen_at, strict=True)) == {0.1: 3.0, 3.0: 8.0}  # type: ignore[arg-type]


@pytest.mark.parametrize(
    "stances, match",
    [
        (np.zeros((2, 2)), "shape"),
        (np.array([[1.0, math.nan, 0.0]]), "non-finite"),
        (np.array([[1.0, 0.5, 0.0]]), "ordered"),
        (np.array([[1.0, 4.0, 0.0], [3.0, 5.0, 1.0]]), "ordered"),
    ],
)
def test_bad_stances_are_refused(stances: np.ndarray, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        NeighborRecord(1, np.zeros((0, 2)), stances=stances)


def test_the_clock_error_enters_the_digest_and_must_be_finite() -> None:
    one = NeighborRecord(1, np.zeros((0, 2)), stances=STANCES)
    other = NeighborRecord(1, np.zeros((0, 2)), stances=STANCES, clock_error=0.05)
    assert records_digest([one]) != records_digest([other])
    for bad in (-0.1, math.nan):
        with pytest.raises(ValueError, match="clock_error"):
            NeighborRecord(1, np.zeros((0, 2)), clock_error=bad)


def test_seen_at_one_per_detection() -> None:
    with pytest.raises(ValueError, match="seen_at"):
        NeighborRecord(1, np.zeros((2, 2)), seen_at=np.array([1.0]))
    with pytest.raises(ValueError, match="seen_at contain non-finite"):
        NeighborRecord(1, np.zeros((1, 2)), seen_at=np.array([math.inf]))


MARGIN = 0.05


@pytest.mark.parametrize(
    "t, margin, want",
    [
        (0.0, MARGIN, 0.0),  # before the search: standing as set down
        (2.5, MARGIN, 0.0),
        (4.0 - MARGIN, MARGIN, 0.0),
        (4.0, MARGIN, math.nan),  # the clocks may disagree: the turn may have begun
        (4.0, 0.0, 0.0),  # one clock: the turn began after the stance's last picture
        (5.5, 0.0, math.nan),  # turning
        (7.0, 0.0, math.pi),
        (7.0, MARGIN, math.nan),
        (8.0, MARGIN, math.pi),
        (10.0, 0.0, math.nan),
        (12.0, 0.0, 0.5),
        (12.0 + MARGIN, MARGIN, 0.5),  # standing until it walks
        (99.0, MARGIN, 0.5),
    ],
)
def test_heading_at_known_answers(t: float, margin: float, want: float) -> None:
    got = heading_at(STANCES, t, margin)
    assert (math.isnan(got) and math.isnan(want)) or got == want


def test_heading_at_without_stances_is_the_start_heading() -> None:
    assert heading_at(None, 5.0) == 0.0 and heading_at(np.zeros((0, 3)), 5.0) == 0.0
    assert math.isnan(heading_at(STANCES, math.nan))


def test_mask_orientation_turns_back_the_targets_stance() -> None:
    owner = NeighborRecord(1, np.array([[1.0, 0.0], [0.0, 1.0], [2.0, 0.0]]),
                           np.array([0.2, 0.2, 0.2]), seen_at=np.array([2.0, 8.0, 5.0]))  # fmt: skip
    target = NeighborRecord(2, np.zeros((0, 2)), stances=STANCES)
    assert mask_orientation(owner, 0, target) == pytest.approx(0.2)
    assert mask_orientation(owner, 1, target) == pytest.approx(0.2 - math.pi)
    assert math.isnan(mask_orientation(owner, 2, target))  # seen mid-turn
    # 8.0 is 1 s inside the stance (7, 9): clocks 0.6 s apart each make it uncertain
    late = NeighborRecord(2, np.zeros((0, 2)), stances=STANCES, clock_error=0.6)
    assert math.isnan(mask_orientation(NeighborRecord(1, owner.neighbours, owner.orientations,
                      seen_at=owner.seen_at, clock_error=0.6), 1, late))  # fmt: skip
    assert mask_orientation(owner, 1, late) == pytest.approx(0.2 - math.pi)
    # without times on either side, or no target: the orientation as recorded
    assert mask_orientation(owner, 2, None) == 0.2
    assert mask_orientation(owner, 2, NeighborRecord(2, np.zeros((0, 2)))) == 0.2
    untimed = NeighborRecord(1, owner.neighbours, owner.orientations)
    assert mask_orientation(untimed, 2, target) == 0.2
    assert math.isnan(mask_orientation(NeighborRecord(1, owner.neighbours), 0, target))


@given(
    theta=st.floats(-math.pi, math.pi),
    h=st.floats(-math.pi, math.pi),
    t=st.floats(0.0, 20.0),
)
def test_mask_orientation_is_the_recorded_one_turned_by_the_stance(
    theta: float, h: float, t: float
) -> None:
    stances = np.array([[0.0, 20.0, h]])
    owner = NeighborRecord(1, np.array([[1.0, 0.0]]), np.array([theta]), seen_at=np.array([t]))
    got = mask_orientation(owner, 0, NeighborRecord(2, np.zeros((0, 2)), stances=stances))
    assert -math.pi <= got <= math.pi
    assert math.cos(got - (theta - h)) == pytest.approx(1.0)
