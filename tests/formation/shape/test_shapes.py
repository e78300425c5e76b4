"""Shapes as data (agent/core/formation/shape/tree.py, builtin.py, spec.py): the tree's
conventions worked by hand, every built-in's scaling rule, the pyramid bit for bit as the
generator of AUV eqs. 5-7, the digest; hypothesis properties for random N and every
built-in (slots pairwise >= 2r apart, the tree connected, offsets composing to the slots)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.formation.shape.builtin import WEDGE_ANGLE, grid_columns
from agent.core.formation.shape.pyramid import parents, right_children, slot_positions
from agent.core.formation.shape.spec import BUILTIN, PYRAMID, TREE, Shape
from agent.core.formation.shape.tree import check_tree, compose, offsets, wrap

D, PHI = 0.8, math.radians(30)
RADIUS = 0.2  # PlanParams' default: slots >= 2 radius apart


def test_offsets_follow_the_parent_s_facing() -> None:
    # 0 ahead, 90° to the left (x is to the right), 180° behind, −90° to the right
    got = offsets(np.full(4, 2.0), np.radians([0.0, 90.0, 180.0, -90.0]))
    np.testing.assert_allclose(got, [[0.0, 2.0], [-2.0, 0.0], [0.0, -2.0], [2.0, 0.0]], atol=1e-12)


def test_compose_sums_the_offsets_from_the_leader() -> None:
    parent = np.array([-1, 0, 1, 1, 3])
    dist = np.array([0.0, 1.0, 1.0, 2.0, 1.0])
    ang = np.radians([0.0, 180.0, 90.0, -90.0, 180.0])
    pos = compose(parent, dist, ang)
    np.testing.assert_allclose(pos, [[0, 0], [0, -1], [-1, -1], [2, -1], [2, -2]], atol=1e-12)


@pytest.mark.parametrize(
    ("parent", "dist", "ang", "match"),
    [
        ([0, 0], [0.0, 1.0], [0.0, 0.0], "leader"),
        ([-1, 1], [0.0, 1.0], [0.0, 0.0], "slot 1: its parent"),
        ([-1, 0, 3, 1], [0.0, 1.0, 1.0, 1.0], [0.0] * 4, "slot 2: its parent"),
        ([-1, 0], [0.0, 0.0], [0.0, 0.0], "distance"),
        ([-1, 0], [0.0, math.inf], [0.0, 0.0], "distance"),
        ([-1, 0], [0.0, 1.0], [0.0, math.nan], "angle"),
        ([-1, 0], [0.0], [0.0, 0.0], "one parent, distance, angle"),
    ],
)
def test_tree_errors(parent: list[int], dist: list[float], ang: list[float], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        check_tree(np.array(parent), np.array(dist), np.array(ang))


def test_wrap() -> None:
    assert wrap(3 * math.pi) == pytest.approx(math.pi)
    assert wrap(-math.pi) == math.pi
    assert wrap(-0.5) == -0.5


@pytest.mark.parametrize("n", [*range(1, 60), 200, 1000, 4097])
def test_the_pyramid_is_the_generator_bit_for_bit(n: int) -> None:
    s = PYRAMID.slots(n, D, PHI)
    assert s.positions.tobytes() == slot_positions(n, D, PHI).tobytes()
    assert s.parent.tolist() == parents(np.arange(n)).tolist()
    # its tree composes to the same slots (within rounding) and sides follow eq. 6
    np.testing.assert_allclose(compose(s.parent, s.distance, s.angle), s.positions, atol=1e-9)
    right = right_children(np.arange(n))
    assert np.all((s.angle[1:] < 0) == right[1:])


def test_built_ins_worked_by_hand() -> None:
    line = BUILTIN["line"].slots(5, D, PHI).positions
    np.testing.assert_allclose(line, [[0, 0], [-D, 0], [D, 0], [-2 * D, 0], [2 * D, 0]], atol=1e-12)
    column = BUILTIN["column"].slots(3, D, PHI).positions
    np.testing.assert_allclose(column, [[0, 0], [0, -D], [0, -2 * D]], atol=1e-12)
    a = D * math.sin(WEDGE_ANGLE)
    wedge = BUILTIN["wedge"].slots(4, D, PHI).positions
    np.testing.assert_allclose(wedge, [[0, 0], [-a, -a], [a, -a], [-2 * a, -2 * a]], atol=1e-12)
    # four on a circle of radius d_e/√2: front, left, right, back
    r = D / math.sqrt(2.0)
    circle = BUILTIN["circle"].slots(4, D, PHI).positions
    np.testing.assert_allclose(circle, [[0, 0], [-r, -r], [r, -r], [0, -2 * r]], atol=1e-12)
    # 7 robots: 3 columns, the leader in the middle of the front row, the short last row
    # under the leader's column
    grid = BUILTIN["grid"].slots(7, D, PHI)
    np.testing.assert_allclose(
        grid.positions,
        [[0, 0], [-D, 0], [D, 0], [0, -D], [-D, -D], [D, -D], [0, -2 * D]],
        atol=1e-12,
    )
    assert grid.parent.tolist() == [-1, 0, 0, 0, 1, 2, 3]


def test_the_grid_s_columns() -> None:
    assert [grid_columns(n) for n in (1, 2, 4, 5, 9, 10, 100, 101)] == [1, 2, 2, 3, 3, 4, 10, 11]
    # 4 columns: the leader in the second, the front row filled left, right, right
    assert BUILTIN["grid"].slots(16, D, PHI).positions[:4, 0] / D == pytest.approx([0, -1, 1, 2])


@pytest.mark.parametrize("n", [3, 5, 8, 13, 40])
def test_the_circle_s_robots_lie_on_it_d_e_apart(n: int) -> None:
    s = BUILTIN["circle"].slots(n, D, PHI).positions
    r = D / (2.0 * math.sin(math.pi / n))
    np.testing.assert_allclose(np.hypot(s[:, 0], s[:, 1] + r), r, atol=1e-9)
    ring = np.sort(np.arctan2(s[:, 1] + r, s[:, 0]))
    np.testing.assert_allclose(np.diff(ring), 2 * math.pi / n, atol=1e-9)


def _pairwise_min(p: np.ndarray) -> float:
    if len(p) < 2:
        return math.inf
    d = np.hypot(*(p[:, None, :] - p[None, :, :]).transpose(2, 0, 1))
    return float(d[~np.eye(len(p), dtype=bool)].min())


@settings(max_examples=60, deadline=None)
@given(
    name=st.sampled_from(sorted(BUILTIN)),
    n=st.integers(1, 150),
    d_e=st.floats(0.4, 3.0),
    phi_deg=st.floats(30.0, 80.0),
)
def test_property_every_built_in(name: str, n: int, d_e: float, phi_deg: float) -> None:
    phi = math.radians(phi_deg)
    s = BUILTIN[name].slots(n, d_e, phi)
    assert s.n == n and s.positions.shape == (n, 2)
    # the tree: slot 0 the leader, every parent earlier (connected, acyclic), d_e edges
    check_tree(s.parent, s.distance, s.angle)
    assert np.allclose(s.positions[0], 0.0)
    assert np.allclose(s.distance[1:], d_e)
    # its offsets compose to the slots, and the slots are pairwise >= d_e (>= 2r) apart;
    # the pyramid's as close as its φ_e makes them: neighbours in a layer 2·d_e·sin φ_e,
    # a slot and the one two layers behind it 2·d_e·cos φ_e
    np.testing.assert_allclose(compose(s.parent, s.distance, s.angle), s.positions, atol=1e-8)
    if name == "pyramid":
        spacing = min(d_e, 2 * d_e * math.sin(phi), 2 * d_e * math.cos(phi))
        assert _pairwise_min(s.positions) >= spacing - 1e-9
    else:
        assert _pairwise_min(s.positions) >= d_e - 1e-9
        assert _pairwise_min(s.positions) >= 2 * RADIUS - 1e-9
    # the leader is at the front: nobody ahead of it
    assert float(np.max(s.positions[:, 1])) <= 1e-9
    # a nested shape: the first slots of a larger fleet are the smaller fleet's
    if BUILTIN[name].nested:
        big = BUILTIN[name].slots(n + 7, d_e, phi)
        np.testing.assert_allclose(big.positions[:n], s.positions, atol=1e-9)


def test_digests_are_stable_and_name_free() -> None:
    assert len({s.digest for s in BUILTIN.values()}) == len(BUILTIN)
    assert PYRAMID.digest == Shape().digest == Shape("my pyramid").digest
    a = Shape("a", TREE, ((0, 1.0, 0.5),))
    assert a.digest == Shape("b", TREE, ((0, 1.0, 0.5),)).digest
    assert a.digest != Shape("a", TREE, ((0, 1.0, 0.5),), "width").digest
    assert a.digest != Shape("a", TREE, ((0, 1.0, 0.5 + 1e-15),)).digest
    assert a.text() == f"a ({a.digest[:12]})"
    # the canonical form is fixed: the pyramid's digest does not change between versions
    assert PYRAMID.digest == "d89f24ee0e4a277e19f8f267ff99b2029973fff360e7e5312eca71550d69be38"


def test_a_tree_shape_holds_its_slots_only() -> None:
    t = Shape("two", TREE, ((0, 1.0, math.pi), (1, 1.0, math.pi)))
    assert t.capacity == 3 and t.nested and BUILTIN["grid"].capacity is None
    s = t.slots(2, D, PHI)
    np.testing.assert_allclose(s.positions, [[0, 0], [0, -1]], atol=1e-12)
    assert s.edge(1) == (0, 1.0, math.pi)
    with pytest.raises(ValueError, match="'two' has 3 slots, too few for 4 robots"):
        t.slots(4, D, PHI)
    t.check_fleet(3)  # the slots it holds; a built-in holds any fleet
    BUILTIN["line"].check_fleet(10**5)
    with pytest.raises(ValueError, match=r"^shape 'two' has 3 slots, too few for 4 robots \("):
        t.check_fleet(4)  # built in code: no file to name
    with pytest.raises(ValueError, match="int >= 1"):
        t.slots(0, D, PHI)
    with pytest.raises(ValueError, match="child slot"):
        s.edge(0)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"name": ""}, "name"),
        ({"rule": "star"}, "rule"),
        ({"orient": "diagonal"}, "orient"),
        ({"rule": TREE}, "at least one child"),
        ({"rule": TREE, "edges": ((1, 1.0, 0.0),)}, "parent"),
        ({"rule": "line", "edges": ((0, 1.0, 0.0),)}, "takes no slots"),
    ],
)
def test_shape_errors(kwargs: dict[str, object], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        Shape(**kwargs)  # type: ignore[arg-type]


@pytest.mark.parametrize("name", sorted(BUILTIN))
def test_built_in_errors(name: str) -> None:
    with pytest.raises(ValueError, match="int >= 1"):
        BUILTIN[name].slots(0, D, PHI)
    with pytest.raises(ValueError, match="d_e"):
        BUILTIN[name].slots(3, -1.0, PHI)
