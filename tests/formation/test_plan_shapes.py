"""The whole plan for every shape (agent/core/formation/plan.py with PlanParams.shape):
the pyramid planned bit for bit as before shapes were data; for random fleets and every
built-in (hypothesis), the slots the tree's, pairwise >= 2r apart, every plan safe by the
timing-robust 2r rule (pairs, and the ``after`` lists with their release points), the
same plan from shuffled input; the shape's digest in the plan's; the banded plan and the
obstacle methods for other shapes."""

from __future__ import annotations

import hashlib
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.formation.params import PlanParams
from agent.core.formation.plan import Plan, plan_from_positions, plan_from_records
from agent.core.formation.shape.spec import BUILTIN, PYRAMID, TREE, Shape
from agent.core.formation.waves.execution import check_dependencies
from agent.core.formation.waves.safety import check_safety
from tests.formation.conftest import random_fleet, records_from_positions

R = 0.2


def fingerprint(plan: Plan) -> str:
    """sha256 of everything a plan holds, its digest included."""
    h = hashlib.sha256(plan.digest.encode())
    h.update(repr((plan.frame_robot, plan.leader, plan.axis, plan.strategy, plan.waves)).encode())
    h.update(repr((plan.excluded, plan.verdict)).encode())
    for a in (plan.origin, plan.psi, plan.obstacles):
        h.update(np.ascontiguousarray(a, "<f8").tobytes())
    for r in plan.robots:
        h.update(repr((r.robot_id, r.order, r.parent, r.heading, r.distance)).encode())
        h.update(repr((r.wave, r.after, r.after_at)).encode())
        h.update(np.ascontiguousarray(r.path(), "<f8").tobytes())
    return h.hexdigest()[:16]


def _case(name: str) -> Plan:
    """The cases of :data:`BEFORE`: fleets of the default, CP, paper, banded, front, lane,
    obstacle and record plans."""
    kind, n = name.rstrip("0123456789"), int(name.lstrip("abcdefghijklmnopqrstuvwxyz"))
    rng = np.random.default_rng([n, 34])
    pos = random_fleet(rng, n, 0.6)
    ids = list(range(100 + n, 100, -1))
    params = {
        "rand": PlanParams(),
        "cp": PlanParams(orientation="cp"),
        "paper": PlanParams(strategy="paper"),
        "banded": PlanParams(strategy="banded"),
        "bandedlayers": PlanParams(strategy="banded", d_e=0.6),
        "front": PlanParams(placement="front"),
        "lanes": PlanParams(d_e=2.0),
        "obs": PlanParams(),
        "obspaper": PlanParams(obstacle_method="paper"),
    }
    if kind == "rec":
        recs = records_from_positions(list(range(n)), pos, noise=0.02, rng=rng)
        return plan_from_records(recs)
    if kind == "lanes":  # a line 1.5 m apart: 23 robots walk in bundle lanes
        rng = np.random.default_rng([n, 34, 2])
        t = (np.arange(n) * 0.75 + rng.uniform(-0.05, 0.05, n)) * 2.0
        off = rng.uniform(-0.1, 0.1, n) * 2.0
        c, s = math.cos(0.7), math.sin(0.7)
        pos = np.c_[t * c - off * s, t * s + off * c]
        ids = list(range(n))
    obs = None
    if kind.startswith("obs"):
        obs = pos.mean(axis=0) + np.array([[0.3, 0.9], [-0.8, 0.1]])
    return plan_from_positions(ids, pos, params[kind], obstacles=obs)


#: Fingerprints of these plans computed by the planner before shapes were data (the
#: pyramid's own slot generator and eq. 6 in the pipeline): the pyramid plans bit for bit
#: as it did.
BEFORE = {
    "rand1": "1de38525e5d2591e",
    "rand2": "a98da52da5e9d9ac",
    "rand3": "59c07ca65ca0dfef",
    "rand5": "ab7ea1a0b3727d40",
    "rand8": "bc21e033d981cd78",
    "rand13": "e306ee707ce75901",
    "rand27": "c3f1ee69a1338b57",
    "cp9": "d1e69bca1ea40666",
    "paper11": "c2df66db91daa67c",
    "banded17": "83e4b9750ae2874a",
    "bandedlayers12": "3e91f3eef2e4e8c0",
    "front10": "604901e2bbe5a743",
    "lanes40": "37b93a0dde55f7fd",
    "obs6": "56c4bc003a4dc8de",
    "obspaper7": "bac407b8602ff2e1",
    "rec6": "b9001fcb45478b86",
}


@pytest.mark.parametrize("name", sorted(BEFORE))
def test_the_pyramid_plans_bit_for_bit_as_before(name: str) -> None:
    assert fingerprint(_case(name)) == BEFORE[name]


def _rows_after(plan: Plan) -> list[list[int]]:
    row = {r.robot_id: k for k, r in enumerate(plan.robots)}
    return [[row[j] for j in r.after] for r in plan.robots]


def assert_shape_plan(plan: Plan, shape: Shape, d_e: float, phi_e: float) -> None:
    """The plan builds ``shape`` and is safe: every child's target at its tree offset from
    its parent's (turned to the plan's axis), slots pairwise >= 2r apart, the 2r rule for
    pairs and for the ``after`` lists with their release points."""
    n = len(plan.robots)
    slots = shape.slots(n, d_e, phi_e)
    by_order = {r.order: r for r in plan.robots}
    assert sorted(by_order) == list(range(n)) and by_order[0].robot_id == plan.leader
    sb, cb = math.sin(plan.axis), math.cos(plan.axis)
    for r in plan.robots:
        p = int(slots.parent[r.order])
        assert r.parent == (-1 if p < 0 else by_order[p].robot_id)
        if p >= 0:
            want = slots.positions[r.order] - slots.positions[p]  # shape frame
            want_c = np.array([want[0] * sb + want[1] * cb, -want[0] * cb + want[1] * sb])
            np.testing.assert_allclose(r.target - by_order[p].target, want_c, atol=1e-9)
    t = plan.targets()
    if n > 1:
        d = np.hypot(*(t[:, None, :] - t[None, :, :]).transpose(2, 0, 1))
        assert d[~np.eye(n, dtype=bool)].min() >= 2 * R - 1e-9
    paths, waves = plan.paths(), plan.wave_of()
    assert check_safety(paths, waves, R) == []
    at: list[list[float]] | None = [list(r.after_at) for r in plan.robots]
    if any(len(r.after_at) != len(r.after) for r in plan.robots):
        at = None  # the banded plan: every robot waited for holds its slot first
    assert check_dependencies(paths, _rows_after(plan), waves, R, after_at=at) == []


coords = st.floats(-6.0, 6.0, allow_nan=False, allow_infinity=False)


@settings(max_examples=40, deadline=None)
@given(
    name=st.sampled_from(sorted(BUILTIN)),
    n=st.integers(1, 14),
    seed=st.integers(0, 10_000),
    strategy=st.sampled_from(["default", "paper", "capt", "banded"]),
    orientation=st.sampled_from(["pca", "cp"]),
)
def test_property_every_built_in_plans_safely_and_alike(
    name: str, n: int, seed: int, strategy: str, orientation: str
) -> None:
    shape = BUILTIN[name]
    rng = np.random.default_rng(seed)
    pos = random_fleet(rng, n, 0.6)
    ids = [int(i) for i in rng.permutation(60)[:n]]
    params = PlanParams(shape=shape, strategy=strategy, orientation=orientation)
    plan = plan_from_positions(ids, pos, params)
    assert_shape_plan(plan, shape, params.d_e, params.phi_e)
    # shuffled input: the same plan, bit for bit
    perm = rng.permutation(n)
    again = plan_from_positions([ids[k] for k in perm], pos[perm], params)
    assert again.digest == plan.digest and fingerprint(again) == fingerprint(plan)


@pytest.mark.parametrize("name", sorted(BUILTIN))
def test_shapes_plan_apart_and_their_digests_differ(name: str) -> None:
    pos = random_fleet(np.random.default_rng(5), 7, 0.6)
    ids = list(range(1, 8))
    plan = plan_from_positions(ids, pos, PlanParams(shape=BUILTIN[name]))
    assert_shape_plan(plan, BUILTIN[name], 0.8, math.radians(30))
    digests = {plan_from_positions(ids, pos, PlanParams(shape=s)).digest for s in BUILTIN.values()}
    assert len(digests) == len(BUILTIN)  # every shape's plan its own
    # the same slots as a formation file: another shape, another digest
    s = BUILTIN[name].slots(7, 0.8, math.radians(30))
    edges = tuple((int(p), float(d), float(a)) for p, d, a in zip(s.parent, s.distance, s.angle))
    as_file = Shape(name, TREE, edges[1:], BUILTIN[name].orient)
    twin = plan_from_positions(ids, pos, PlanParams(shape=as_file))
    assert twin.digest != plan.digest
    np.testing.assert_allclose(twin.targets(), plan.targets(), atol=1e-9)


@pytest.mark.parametrize("name", ["line", "column", "circle", "grid"])
@pytest.mark.parametrize("n", [40, 130])
def test_the_banded_plan_for_other_shapes(name: str, n: int) -> None:
    pos = random_fleet(np.random.default_rng(n), n, 0.6)
    for d_e in (0.6, 0.8):  # layer blocks and slot columns
        params = PlanParams(shape=BUILTIN[name], strategy="banded", d_e=d_e)
        plan = plan_from_positions(list(range(n)), pos, params)
        assert plan.strategy == "banded"
        assert_shape_plan(plan, BUILTIN[name], d_e, params.phi_e)


@pytest.mark.parametrize("name", ["line", "wedge", "grid"])
def test_obstacles_near_for_any_shape_paper_for_nested_ones(name: str) -> None:
    pos = random_fleet(np.random.default_rng(9), 6, 0.6)
    obs = pos.mean(axis=0) + np.array([[0.3, 0.9], [-0.8, 0.1]])
    shape = BUILTIN[name]
    plan = plan_from_positions(list(range(6)), pos, PlanParams(shape=shape), obstacles=obs)
    assert_shape_plan(plan, shape, 0.8, math.radians(30))
    paper = PlanParams(shape=shape, obstacle_method="paper")
    if shape.nested:
        plan = plan_from_positions(list(range(6)), pos, paper, obstacles=obs)
        assert_shape_plan(plan, shape, 0.8, math.radians(30))
    else:
        with pytest.raises(ValueError, match="first N slots"):
            plan_from_positions(list(range(6)), pos, paper, obstacles=obs)


def test_a_file_shape_with_too_few_slots_plans_nothing() -> None:
    two = Shape("two", TREE, ((0, 1.0, math.pi),))
    pos = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    with pytest.raises(ValueError, match="2 slots, too few for 3 robots"):
        plan_from_positions([1, 2, 3], pos, PlanParams(shape=two))
    assert PYRAMID.capacity is None
