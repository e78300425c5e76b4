"""The transition planner (agent/core/formation/reshape.py): the new shape from the held
slots, safe, identical from any input order, its digest chained; the command's shape."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.formation.params import PlanParams
from agent.core.formation.plan import Plan, plan_from_positions, plan_from_records
from agent.core.formation.reshape import command_shape, transition_plan
from agent.core.formation.shape.spec import BUILTIN, PYRAMID, TREE, Shape
from tests.formation.conftest import random_fleet, records_from_positions
from tests.formation.test_plan_shapes import assert_shape_plan, fingerprint

P = PlanParams()
LINE, WEDGE = BUILTIN["line"], BUILTIN["wedge"]


def held(n: int, seed: int = 3, shape: Shape = PYRAMID) -> Plan:
    rng = np.random.default_rng([n, seed])
    return plan_from_positions(
        list(range(1, n + 1)), random_fleet(rng, n, 0.6), replace(P, shape=shape)
    )


def test_known_answer_four_robots_pyramid_to_line() -> None:
    """Four robots holding the pyramid's slots: the line's slots d_e apart along one
    straight line through their mean, every robot starting on its held slot."""
    pyramid = plan_from_positions([1, 2, 3, 4], np.array([[0, 0], [2, 0], [0, 2], [2, 2]]), P)
    line = transition_plan(pyramid, LINE, P)
    assert line.ids == (1, 2, 3, 4)
    np.testing.assert_array_equal(line.starts(), pyramid.targets())
    assert_shape_plan(line, LINE, P.d_e, P.phi_e)
    t = line.targets()
    # collinear, neighbours d_e apart, centred where the pyramid's slots were
    u = t - t.mean(axis=0)
    assert np.linalg.matrix_rank(u, tol=1e-9) == 1
    along = np.sort(u @ (u[np.argmax(np.hypot(*u.T))] / np.max(np.hypot(*u.T))))
    np.testing.assert_allclose(np.diff(along), P.d_e, atol=1e-9)
    assert line.digest != pyramid.digest and len(line.digest) == 64
    # the digest chains the held plan's: the same line from another held plan differs
    other = plan_from_positions([1, 2, 3, 4], np.array([[0, 0], [2, 0], [0, 2], [2, 2.5]]), P)
    assert transition_plan(other, LINE, P).digest != line.digest
    assert fingerprint(transition_plan(pyramid, LINE, P)) == fingerprint(line)


@pytest.mark.parametrize("n", [3, 5, 8])
@pytest.mark.parametrize("to", ["line", "wedge", "column", "circle", "grid", "pyramid"])
def test_every_builtin_from_a_held_pyramid_is_safe(n: int, to: str) -> None:
    plan = transition_plan(held(n), BUILTIN[to], P)
    assert_shape_plan(plan, BUILTIN[to], P.d_e, P.phi_e)
    np.testing.assert_array_equal(plan.starts(), held(n).targets())


def test_pyramid_line_wedge_chain_of_eight() -> None:
    first = held(8)
    line = transition_plan(first, LINE, P)
    wedge = transition_plan(line, WEDGE, P)
    assert_shape_plan(wedge, WEDGE, P.d_e, P.phi_e)
    np.testing.assert_array_equal(wedge.starts(), line.targets())
    assert len({first.digest, line.digest, wedge.digest}) == 3
    assert wedge.digest != transition_plan(first, WEDGE, P).digest


@settings(max_examples=25, deadline=None)
@given(st.integers(2, 9), st.integers(0, 10_000), st.sampled_from(sorted(BUILTIN)))
def test_shuffled_robots_give_the_same_transition(n: int, seed: int, to: str) -> None:
    base = held(n, seed)
    order = np.random.default_rng(seed).permutation(n)
    shuffled = replace(base, robots=tuple(base.robots[k] for k in order))
    a, b = transition_plan(base, BUILTIN[to], P), transition_plan(shuffled, BUILTIN[to], P)
    assert fingerprint(a) == fingerprint(b)
    assert_shape_plan(a, BUILTIN[to], P.d_e, P.phi_e)


def test_headings_and_left_out_robots_carry_over() -> None:
    rng = np.random.default_rng(5)
    pos = random_fleet(rng, 5, 0.6)
    first = plan_from_records(records_from_positions(list(range(1, 6)), pos), P)
    turned = replace(first, psi=np.linspace(0.1, 0.5, 5), excluded=(), verdict="v")
    plan = transition_plan(turned, LINE, P)
    np.testing.assert_array_equal(plan.psi, turned.psi)
    assert plan.verdict == "v"
    assert plan.digest != transition_plan(replace(turned, psi=np.zeros(5)), LINE, P).digest
    # robots given in another order: each keeps its own ψ
    rev = replace(turned, robots=turned.robots[::-1], psi=turned.psi[::-1])
    np.testing.assert_array_equal(transition_plan(rev, LINE, P).psi, turned.psi)


def test_obstacles_of_the_held_plan_are_planned_around() -> None:
    base = held(4)
    far = base.targets().mean(axis=0) + np.array([6.0, 6.0])
    with_obs = replace(base, obstacles=far.reshape(1, 2))
    plan = transition_plan(with_obs, LINE, P)
    np.testing.assert_array_equal(plan.obstacles, far.reshape(1, 2))


def test_transition_errors() -> None:
    with pytest.raises(ValueError, match="no robots"):
        transition_plan(replace(held(3), robots=()), LINE, P)
    tree = Shape("two", TREE, ((0, 0.8, 3.0),))
    with pytest.raises(ValueError, match="has 2 slots, too few for 3 robots"):
        transition_plan(held(3), tree, P)
    tight = Shape("tight", TREE, ((0, 0.1, 3.0), (0, 0.8, 2.0)))
    with pytest.raises(ValueError):
        transition_plan(held(3), tight, P)


def test_command_shape_builds_the_shape_its_digest_names() -> None:
    assert command_shape("line", "line", "width", (), LINE.digest) == LINE
    edges = ((0, 0.8, 2.4), (0, 0.8, -2.4))
    tree = Shape("v", TREE, edges, "width")
    got = command_shape("v", TREE, "width", edges, tree.digest)
    assert got == tree and got.digest == tree.digest
    with pytest.raises(ValueError, match="the command says"):
        command_shape("line", "line", "width", (), WEDGE.digest)
    with pytest.raises(ValueError, match="shape rule must be one of"):
        command_shape("x", "spiral", "depth", (), LINE.digest)
    with pytest.raises(ValueError, match="takes no slots"):
        command_shape("line", "line", "width", edges, LINE.digest)
    with pytest.raises(ValueError, match="orient"):
        command_shape("line", "line", "sideways", (), LINE.digest)
