"""sim/server/bindings.py: who may claim and drive which robot, without zenoh
(docs/design.md §8)."""

from __future__ import annotations

import pytest

from agent.wire.trust import Identity
from sim.server.bindings import RobotBindings, Unauthorised


def test_register_hands_out_the_lowest_free_id_and_tokens_take_ids() -> None:
    b = RobotBindings((1, 2, 3))
    assert b.register(None, -1, 2) == 2
    with pytest.raises(ValueError, match="already claimed"):
        b.register(None, -1, 2)
    assert not b.token(1, gone=False)  # an agent with a fixed --id 1
    with pytest.raises(ValueError, match="driven by a live agent"):
        b.register(None, -1, 1)
    assert b.register(None, -1, -1) == 3
    with pytest.raises(ValueError, match="every robot is claimed"):
        b.register(None, -1, -1)
    with pytest.raises(ValueError, match="not in this world"):
        b.register(None, -1, 42)
    assert b.token(2, gone=True)  # the claim is released with the token
    assert not b.token(1, gone=True)  # a token without a claim
    assert b.claims == {3} and b.alive == set()
    assert b.register(None, -1, -1) == 1


def test_a_key_claims_its_own_robot_only_and_binds_the_session() -> None:
    b = RobotBindings((1, 2, 3))
    with pytest.raises(ValueError, match="may not claim robot 3"):
        b.register(Identity.robot(2), 7, 3)
    with pytest.raises(ValueError, match="not a robot"):
        b.register(Identity("observer"), 7, -1)
    assert b.register(Identity.robot(2), 7, -1) == 2
    assert b.bound == {2: 7}
    b.authorise(Identity.robot(2), 7, 2)
    with pytest.raises(Unauthorised, match="may not command robot 1"):
        b.authorise(Identity.robot(2), 7, 1)
    with pytest.raises(Unauthorised, match="nobody may not command robot 2"):
        b.authorise(None, 7, 2)
    with pytest.raises(Unauthorised, match="bound to another session"):
        b.authorise(Identity.robot(2), 8, 2)  # claimed: even a newer session is refused


def test_a_fixed_id_is_bound_to_the_newest_session_of_its_key() -> None:
    b = RobotBindings((1, 2, 3))
    b.authorise(Identity.robot(1), 5, 1)
    b.authorise(Identity.robot(1), 6, 1)  # a restart takes the unclaimed robot over
    with pytest.raises(Unauthorised, match="bound to another session"):
        b.authorise(Identity.robot(1), 5, 1)  # the old session (a replay) is refused
    assert b.bound == {1: 6}
