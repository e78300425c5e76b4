"""Walking, turning, noise statistics and contacts (sim/physics/locomotion.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agent.wire import MAX_SIDE_STEP
from sim.physics.locomotion import (
    DT,
    SIDE_SPEED,
    WALK_SPEED,
    Locomotion,
    NoiseModel,
    Obstacle,
)
from sim.physics.nao_model import FOOTPRINT_RADIUS
from sim.physics.world import World
from sim.scenarios import RobotSpec, Scenario

NORTH = math.pi / 2


class Store:
    """A plain pose table (the part of World that locomotion uses)."""

    def __init__(self, poses: dict[int, tuple[float, float, float]]) -> None:
        self.p = dict(poses)
        self.robot_ids = tuple(sorted(poses))

    def pose(self, robot_id: int) -> tuple[float, float, float]:
        return self.p[robot_id]

    def set_pose(self, robot_id: int, x: float, y: float, heading: float) -> None:
        self.p[robot_id] = (x, y, heading)


def test_noiseless_walk_is_exact_and_takes_distance_over_speed() -> None:
    st = Store({1: (0.0, 0.0, NORTH)})
    loco = Locomotion(st, seed=0, noise=NoiseModel.none())
    loco.walk(1, 0.2)
    assert loco.busy(1)
    done, contacts = loco.run_until_idle()
    assert contacts == []
    assert [(d.robot_id, d.kind, d.status) for d in done] == [(1, "walk", "done")]
    x, y, th = st.pose(1)
    assert x == pytest.approx(0.0, abs=1e-12)
    assert y == pytest.approx(0.2, abs=1e-12)
    assert th == NORTH
    steps = math.ceil(0.2 / (WALK_SPEED * DT) - 1e-9)
    assert loco.t_sim == pytest.approx(steps * DT)


def test_noiseless_turn_and_backwards_walk() -> None:
    st = Store({1: (0.0, 0.0, NORTH)})
    loco = Locomotion(st, seed=0, noise=NoiseModel.none())
    loco.turn(1, -math.pi / 2)
    loco.run_until_idle()
    assert st.pose(1)[2] == pytest.approx(0.0, abs=1e-12)
    loco.walk(1, -0.3)
    loco.run_until_idle()
    assert st.pose(1)[0] == pytest.approx(-0.3, abs=1e-12)


def test_noiseless_sidesteps_are_exact_and_take_distance_over_their_speed() -> None:
    st = Store({1: (0.0, 0.0, NORTH)})
    loco = Locomotion(st, seed=0, noise=NoiseModel.none())
    loco.side(1, 0.1)  # facing north: to the left is west
    done, _ = loco.run_until_idle()
    assert [(d.kind, d.status) for d in done] == [("side", "done")]
    assert st.pose(1) == pytest.approx((-0.1, 0.0, NORTH), abs=1e-12)
    assert loco.t_sim == pytest.approx(math.ceil(0.1 / (SIDE_SPEED * DT) - 1e-9) * DT)
    loco.side(1, -0.25)
    loco.run_until_idle()
    assert st.pose(1) == pytest.approx((0.15, 0.0, NORTH), abs=1e-12)


@pytest.mark.parametrize(
    ("distance", "reason"), [(math.nan, "not finite"), (MAX_SIDE_STEP + 0.01, "exceeds")]
)
def test_impossible_sidesteps_are_refused(distance: float, reason: str) -> None:
    loco = Locomotion(Store({1: (0.0, 0.0, NORTH)}), seed=0)
    with pytest.raises(ValueError, match=reason):
        loco.side(1, distance)
    loco.walk(1, 0.1)
    with pytest.raises(ValueError, match="busy"):
        loco.side(1, 0.05)


def _walk_errors(distance: float, runs: int) -> tuple[np.ndarray, np.ndarray]:
    heading_err, dist_err = [], []
    for seed in range(runs):
        st = Store({1: (0.0, 0.0, NORTH)})
        loco = Locomotion(st, seed=seed)
        loco.walk(1, distance)
        loco.run_until_idle()
        x, y, th = st.pose(1)
        heading_err.append(th - NORTH)
        dist_err.append(math.hypot(x, y) - distance)
    return np.array(heading_err), np.array(dist_err)


def test_noise_statistics_match_table_2_magnitudes() -> None:
    # Table 2 (NAO paper): |heading error| about 0.02-0.10 rad after 0.2 m and
    # 0.33-0.45 rad after 0.8-1.0 m. Over robots the model's sigma is 0.09 rad at 0.2 m
    # and 0.37 rad at 1.0 m; 300 seeded robots estimate it within about ±10 %.
    h02, d02 = _walk_errors(0.2, 300)
    h10, d10 = _walk_errors(1.0, 300)
    rms02, rms10 = float(np.sqrt(np.mean(h02**2))), float(np.sqrt(np.mean(h10**2)))
    assert 0.07 < rms02 < 0.12
    assert 0.30 < rms10 < 0.45
    assert 0.05 < float(np.mean(np.abs(h02))) < 0.12  # Table 2 mean |e| at 0.2 m: ~0.11
    assert 0.25 < float(np.mean(np.abs(h10))) < 0.45  # at 0.8-1.0 m: ~0.40
    assert abs(float(np.mean(h10))) < 0.06  # unbiased
    # Distance: unbiased, 4 % relative error (the curve makes the chord slightly shorter).
    assert abs(float(np.mean(d10))) < 0.02
    assert 0.025 < float(np.std(d10)) < 0.06
    assert float(np.std(d02)) < 0.015


def test_noise_scale_multiplies_every_sigma() -> None:
    base = NoiseModel()
    assert NoiseModel().scaled(1.0) == base
    assert NoiseModel().scaled(0.0) == NoiseModel.none()
    twice = base.scaled(2.0)
    assert twice.curvature_bias == 2 * base.curvature_bias
    assert twice.turn_offset == 2 * base.turn_offset
    # the heading error after a segment grows with the scale (same seeds, same draws)
    errs = {}
    for k in (1.0, 2.0):
        e = []
        for seed in range(40):
            st = Store({1: (0.0, 0.0, NORTH)})
            loco = Locomotion(st, seed=seed, noise=base.scaled(k))
            loco.walk(1, 0.5)
            loco.run_until_idle()
            e.append(st.pose(1)[2] - NORTH)
        errs[k] = np.array(e)
    # the same seeds draw the same normals: the heading errors about double (the
    # scaled distance error changes the number of random-walk steps a little)
    ratio = float(np.sqrt(np.mean(errs[2.0] ** 2) / np.mean(errs[1.0] ** 2)))
    assert 1.7 < ratio < 2.3, ratio


@pytest.mark.parametrize("k", [-0.1, math.nan, math.inf, 10.5])
def test_noise_scale_out_of_range(k: float) -> None:
    with pytest.raises(ValueError, match="noise scale"):
        NoiseModel().scaled(k)


def test_each_robot_veers_to_its_own_side() -> None:
    # Eight 0.5 m walks per robot, the heading reset to north before each: a robot's mean
    # error is its own drift x 0.5 m (sigma 0.15 rad over robots), the spread around that
    # mean the per-command part (sigma 0.12 rad).
    means, spreads = [], []
    for seed in range(80):
        st = Store({1: (0.0, 0.0, NORTH)})
        loco = Locomotion(st, seed=seed)
        errs = []
        for _ in range(8):
            st.set_pose(1, 0.0, 0.0, NORTH)
            loco.walk(1, 0.5)
            loco.run_until_idle()
            errs.append(st.pose(1)[2] - NORTH)
        means.append(float(np.mean(errs)))
        spreads.append(float(np.std(errs, ddof=1)))
        assert np.mean(errs) == pytest.approx(loco.drift[1] * 0.5, abs=0.15)
    assert 0.11 < float(np.std(means)) < 0.20
    assert 0.08 < float(np.mean(spreads)) < 0.16


def test_turn_noise_statistics() -> None:
    errs = []
    for seed in range(300):
        st = Store({1: (0.0, 0.0, NORTH)})
        loco = Locomotion(st, seed=seed)
        loco.turn(1, math.radians(15.0))
        loco.run_until_idle()
        errs.append(st.pose(1)[2] - NORTH - math.radians(15.0))
    e = np.array(errs)
    expected = math.hypot(0.05 * math.radians(15.0), 0.02)
    assert float(np.std(e)) == pytest.approx(expected, rel=0.15)
    assert abs(float(np.mean(e))) < 0.005


def test_same_seed_same_walk_other_robots_do_not_matter() -> None:
    a = Store({1: (0.0, 0.0, NORTH)})
    la = Locomotion(a, seed=5)
    la.walk(1, 0.6)
    la.run_until_idle()
    b = Store({1: (0.0, 0.0, NORTH), 2: (3.0, 0.0, NORTH)})
    lb = Locomotion(b, seed=5)
    lb.walk(1, 0.6)
    lb.walk(2, 0.2)
    lb.run_until_idle()
    assert a.pose(1) == b.pose(1)


def test_two_robots_walked_into_each_other_stop_and_the_contact_is_reported() -> None:
    sc = Scenario(robots=(RobotSpec(1, 0.0, 0.0, NORTH), RobotSpec(2, 0.0, 1.0, -NORTH)), seed=1)
    with World(sc, noise=False) as w:
        loco = w.locomotion
        loco.walk(1, 1.0)
        loco.walk(2, 1.0)
        done, contacts = loco.run_until_idle()
        assert sorted((d.robot_id, d.status) for d in done) == [(1, "contact"), (2, "contact")]
        assert [(c.a, c.b) for c in contacts] == [(1, 2)]
        assert loco.contacts == 1
        gap = w.pose(2)[1] - w.pose(1)[1]
        assert 2 * FOOTPRINT_RADIUS - 0.01 < gap < 2 * FOOTPRINT_RADIUS + 0.01
        assert "robot 2" in next(d.detail for d in done if d.robot_id == 1)
        # Backing away is allowed.
        loco.walk(1, -0.2)
        done, contacts = loco.run_until_idle()
        assert [d.status for d in done] == ["done"] and contacts == []


def test_walking_into_a_standing_robot_stops_both() -> None:
    st = Store({1: (0.0, 0.0, NORTH), 2: (0.0, 0.5, NORTH)})
    loco = Locomotion(st, seed=0, noise=NoiseModel.none())
    loco.turn(2, 0.5)
    loco.walk(1, 1.0)
    done, contacts = loco.run_until_idle()
    assert {d.robot_id: d.status for d in done} == {1: "contact", 2: "done"} or {
        d.robot_id: d.status for d in done
    } == {1: "contact", 2: "contact"}
    assert len(contacts) == 1
    assert st.pose(2)[:2] == (0.0, 0.5)


def test_obstacle_and_wall_contacts() -> None:
    st = Store({1: (0.0, 0.0, NORTH), 2: (1.0, 0.0, 0.0)})
    loco = Locomotion(
        st, seed=0, noise=NoiseModel.none(), obstacles=(Obstacle(0.0, 1.0, 0.2),), room=2.0
    )
    loco.walk(1, 2.0)
    loco.walk(2, 2.0)
    done, contacts = loco.run_until_idle()
    assert sorted((c.a, c.b) for c in contacts) == [(1, -1), (2, -1)]
    assert all(d.status == "contact" for d in done)
    assert st.pose(1)[1] == pytest.approx(1.0 - 0.2 - FOOTPRINT_RADIUS, abs=0.005)
    assert st.pose(2)[0] == pytest.approx(2.0 - FOOTPRINT_RADIUS, abs=0.005)


@pytest.mark.parametrize(
    ("call", "value", "reason"),
    [
        ("walk", math.nan, "not finite"),
        ("walk", math.inf, "not finite"),
        ("walk", 51.0, "exceeds"),
        ("turn", math.nan, "not finite"),
        ("turn", 20.0, "exceeds"),
    ],
)
def test_bad_commands(call: str, value: float, reason: str) -> None:
    loco = Locomotion(Store({1: (0.0, 0.0, NORTH)}), seed=0)
    with pytest.raises(ValueError, match=reason):
        getattr(loco, call)(1, value)
    assert not loco.busy(1)


def test_unknown_robot_and_busy_robot() -> None:
    loco = Locomotion(Store({1: (0.0, 0.0, NORTH)}), seed=0)
    with pytest.raises(ValueError, match="unknown robot"):
        loco.walk(7, 0.2)
    loco.walk(1, 0.2)
    with pytest.raises(ValueError, match="busy"):
        loco.turn(1, 0.2)


def test_bad_time_step() -> None:
    with pytest.raises(ValueError, match="time step"):
        Locomotion(Store({1: (0.0, 0.0, NORTH)}), seed=0, dt=0.0)


def test_clock_does_not_move_when_idle() -> None:
    loco = Locomotion(Store({1: (0.0, 0.0, NORTH)}), seed=0)
    assert loco.step() == ([], [])
    assert loco.t_sim == 0.0
