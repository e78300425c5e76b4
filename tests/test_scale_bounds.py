"""The bounds that let 100 NAOs run: each raised, none removed.

- ``tools.demo --robots`` in [1, MAX_ROBOTS = 128];
- a record carries at most ``MAX_NEIGHBOURS`` = 128 neighbours; the largest record fits
  ``MAX_RECORD_BYTES`` (a record set's item), a signed publication and a journal state;
- the scenario generator places 100 robots in a room of the world's bounds, and nobody
  there has more robots within sight than a record may carry;
- what a member hears of the fleet's progress statuses stays bounded.
"""

from __future__ import annotations

import math

import pytest

from agent import wire as w
from agent.core import nao
from agent.recovery.journal import JournalState, decode_state, encode_state
from sim import scenarios
from tools.demo import parse_args
from tools.harness.fleet import MAX_ROBOTS


def largest_record(k: int = w.MAX_NEIGHBOURS) -> w.NeighborRecordMsg:
    """A record with ``k`` neighbours and every obstacle, each number as long as msgpack
    makes it (float64, the widest ids and rounds)."""
    return w.NeighborRecordMsg(
        sender=w.MAX_ROBOT_ID,
        round=1_000_000,
        neighbours=tuple((-123.456789 + i, 98.7654321) for i in range(k)),
        orientations=tuple(-3.14159 for _ in range(k)),
        confidences=tuple(0.123456 for _ in range(k)),
        obstacles=tuple((1.5, -2.5) for _ in range(w.MAX_OBSTACLES)),
    )


def test_the_demo_runs_up_to_128_robots() -> None:
    assert MAX_ROBOTS == 128
    assert parse_args(["--robots", "100"]).robots == 100
    assert parse_args(["--robots", str(MAX_ROBOTS)]).robots == MAX_ROBOTS
    for bad in ("0", str(MAX_ROBOTS + 1)):
        with pytest.raises(SystemExit):
            parse_args(["--robots", bad])


def test_a_record_of_a_full_fleet_fits_every_bound() -> None:
    assert w.MAX_NEIGHBOURS == 128 and w.MAX_NEIGHBOURS >= MAX_ROBOTS - 1
    rec = largest_record()
    data = w.encode(rec)
    assert len(data) <= w.MAX_RECORD_BYTES
    assert w.decode(data) == rec
    assert len(data) + 512 <= w.MAX_PUBLICATION_BYTES  # with its signed envelope
    members = tuple(range(w.MAX_MEMBERS))
    state = JournalState(
        robot_id=w.MAX_ROBOT_ID, record=rec, agreed_digest="a" * 64, agreed_members=members
    )
    assert decode_state(encode_state(state)).record == rec
    reply = w.RecordSetReply(sender=1, digest="a" * 64, records=(data,) * MAX_ROBOTS)
    assert len(w.encode(reply)) <= w.MAX_MESSAGE_BYTES


def test_more_neighbours_than_the_bound_are_refused() -> None:
    with pytest.raises(ValueError, match="at most"):
        largest_record(w.MAX_NEIGHBOURS + 1)
    raw = w.encode(largest_record())
    with pytest.raises(ValueError):
        w.RecordSetReply(sender=1, digest="a" * 64, records=(raw + b"x" * w.MAX_RECORD_BYTES,))


def test_a_generated_fleet_of_100_fits_the_room_and_the_records() -> None:
    sc = scenarios.generate(100, 1)
    scenarios.validate(sc)
    assert len(sc.robots) == 100 and sc.room <= 100.0
    pos = [(r.x, r.y) for r in sc.robots]
    in_sight = max(
        sum(0 < math.dist(p, q) <= nao.SIGHT_MAX for q in pos) for p in pos
    )  # a robot detects nobody beyond sight
    assert in_sight < w.MAX_NEIGHBOURS
    with pytest.raises(ValueError, match="200"):
        scenarios.generate(201, 1)


def test_status_cadence_is_bounded_by_what_a_member_hears() -> None:
    """Known answers: 3 s up to 30 NAOs, then fleet / 10 statuses a second (so that 100 NAOs do not
    flood each other)."""
    from agent.phases.reporting import STATUS_MIN_INTERVAL, status_interval

    assert status_interval(None) == STATUS_MIN_INTERVAL == 3.0
    assert status_interval(3) == status_interval(30) == 3.0
    assert status_interval(50) == pytest.approx(5.0)
    assert status_interval(100) == pytest.approx(10.0)
