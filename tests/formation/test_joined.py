"""Robots joined by pairs (agent/core/formation/joined.py): known answers, a property
against scipy's disjoint sets, and each error branch."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.cluster.hierarchy import DisjointSet

from agent.core.formation.joined import Joined


def test_known_answer() -> None:
    j = Joined([5, 1, 3, 9])
    assert j.merge(1, 3) and j.merge(9, 5) and not j.merge(3, 1)
    assert j.root(1) == j.root(3) != j.root(5)
    assert sorted(sorted(s) for s in j.subsets()) == [[1, 3], [5, 9]]


@given(st.lists(st.tuples(st.integers(0, 11), st.integers(0, 11)), max_size=40))
def test_the_same_sets_and_merges_as_scipy(pairs: list[tuple[int, int]]) -> None:
    ours, theirs = Joined(range(12)), DisjointSet(range(12))
    for a, b in pairs:
        assert ours.merge(a, b) == theirs.merge(a, b)
    assert sorted(sorted(s) for s in ours.subsets()) == sorted(sorted(s) for s in theirs.subsets())


def test_errors() -> None:
    with pytest.raises(ValueError, match="twice"):
        Joined([1, 1])
    j = Joined([1, 2])
    with pytest.raises(ValueError, match="unknown"):
        j.merge(1, 7)
    with pytest.raises(ValueError, match="unknown"):
        j.root(0)
