"""Robots joined by pairs: a disjoint-set forest (union by size, path halving).

The frame needs which robots the identified pairs connect: the connected groups of the
re-search rule (NAO paper 4.1.3, docs/design.md §1, Plan) and Kruskal's spanning forest
of the firm pairs (docs/design.md §9). A dozen lines here keep the agents from importing
``scipy.cluster`` (and with it ``scipy.stats``) for it: with the χ² tails taken from
``scipy.special``, an agent's imports fall from 2.2 s to 1.2 s (measured with
``python -X importtime``, load 3).
"""

from __future__ import annotations

from collections.abc import Iterable


class Joined:
    """Disjoint sets over the given ids (each its own set at first).

    Raises
    ------
    ValueError
        On an id given twice, or :meth:`merge` of an id not given.
    """

    def __init__(self, ids: Iterable[int]) -> None:
        self._parent: dict[int, int] = {}
        self._size: dict[int, int] = {}
        for i in ids:
            if i in self._parent:
                raise ValueError(f"id {i} given twice")
            self._parent[i] = i
            self._size[i] = 1

    def root(self, i: int) -> int:
        """The representative of ``i``'s set."""
        if i not in self._parent:
            raise ValueError(f"unknown id {i}")
        parent = self._parent
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    def merge(self, a: int, b: int) -> bool:
        """Join the sets of ``a`` and ``b``; True when they were apart."""
        ra, rb = self.root(a), self.root(b)
        if ra == rb:
            return False
        if self._size[ra] < self._size[rb]:
            ra, rb = rb, ra
        self._parent[rb] = ra
        self._size[ra] += self._size[rb]
        return True

    def subsets(self) -> list[set[int]]:
        """Every set, in the order of its first id as given."""
        out: dict[int, set[int]] = {}
        for i in self._parent:
            out.setdefault(self.root(i), set()).add(i)
        return list(out.values())
