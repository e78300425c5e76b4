"""Membership grace (agent/core/grace.py): a vanished liveliness token counts as a
departure only after the grace period, unless the member is heard again (a lossy radio)."""

from __future__ import annotations

import math

import pytest

from agent.core.grace import Grace


def test_grace_a_vanished_token_is_gone_only_after_the_grace_period() -> None:
    g = Grace(5.0)
    g.token(1, False, 10.0)
    assert g.pending() == (1,)
    assert g.expired(14.9) == []
    assert g.expired(15.0) == [1]
    assert g.pending() == () and g.expired(100.0) == []  # reported once


def test_grace_heartbeats_and_a_returning_token_end_the_count() -> None:
    g = Grace(5.0)
    g.token(1, False, 0.0)
    g.token(2, False, 0.0)
    g.heard(1, 4.0)  # a record or status of robot 1: still there
    g.heard(3, 4.0)  # no token lost: nothing to reset
    g.token(2, True, 3.0)  # robot 2 reconnected
    assert g.expired(8.0) == []
    assert g.expired(9.0) == [1]
    g.token(4, False, 0.0)
    g.token(4, False, 7.0)  # a repeated vanish does not restart the count
    assert g.expired(5.0) == [4]


def test_grace_zero_expires_at_once_and_bad_grace_is_refused() -> None:
    g = Grace(0.0)
    g.token(1, False, 2.0)
    assert g.expired(2.0) == [1]
    for bad in (-1.0, math.inf, math.nan):
        with pytest.raises(ValueError, match="grace"):
            Grace(bad)
