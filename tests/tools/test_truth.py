"""tools/harness/truth.py: who moved and the formation's shape, from true poses alone (known
answers worked by hand; every built-in shape judged right wherever it faces, and wrong when
a child stands off its tree offset)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agent.core.formation.params import D_E, PHI_E_DEG
from agent.core.formation.shape.pyramid import slot_positions
from agent.core.formation.shape.spec import BUILTIN, PYRAMID, Shape
from tools.harness.pairs import evaluate
from tools.harness.truth import (
    Link,
    check_shape,
    excursions,
    judge_shape,
    settled_at,
    slot_links,
)

D, PHI = D_E, math.radians(PHI_E_DEG)


def placed(
    slots: np.ndarray, facing: float, origin: tuple[float, float] = (0.0, 0.0)
) -> dict[int, tuple]:
    """Robots 1..n on ``slots`` (shape frame) turned to face ``facing``, headings ``facing``."""
    fwd = np.array([math.cos(facing), math.sin(facing)])
    left = np.array([-fwd[1], fwd[0]])
    return {
        k + 1: (*(np.array(origin) + s[1] * fwd - s[0] * left), facing) for k, s in enumerate(slots)
    }


def pyramid(n: int, facing: float, origin: tuple[float, float] = (0.0, 0.0)) -> dict[int, tuple]:
    """Robots 1..n on the slots of a pyramid of n facing ``facing``, headings ``facing``."""
    return placed(slot_positions(n, D, PHI), facing, origin)


LEFT_CHILD, RIGHT_CHILD = math.pi - PHI, PHI - math.pi  # the pyramid's tree angles


def test_the_slot_links_are_the_pyramids_definition() -> None:
    tree = slot_links(PYRAMID, 6, D, PHI)
    assert [p for p, _, _ in tree] == [-1, 0, 0, 1, 2, 2]
    assert [a for _, _, a in tree] == pytest.approx(
        [0.0, LEFT_CHILD, RIGHT_CHILD, LEFT_CHILD, LEFT_CHILD, RIGHT_CHILD]
    )
    # every side as the slots place it: a left child lies left (x smaller) of its parent
    s = slot_positions(10, D, PHI)
    for k, (p, d, a) in enumerate(slot_links(PYRAMID, 10, D, PHI)[1:], start=1):
        side = 1.0 if a > 0 else -1.0
        assert d == D
        assert side * (s[p, 0] - s[k, 0]) == pytest.approx(D * math.sin(PHI))
        assert s[p, 1] - s[k, 1] == pytest.approx(D * math.cos(PHI))


@pytest.mark.parametrize("n", [1, 2, 3, 4, 6, 10])
@pytest.mark.parametrize("facing", [math.pi / 2, 0.3, -2.5])
def test_a_true_pyramid_is_judged_right_whichever_way_it_faces(n: int, facing: float) -> None:
    shape = judge_shape(pyramid(n, facing, (2.0, -1.0)), list(range(1, n + 1)), D, PHI)
    assert shape.ok and shape.leader == 1 and shape.leader_in_front
    assert shape.facing == pytest.approx(facing)
    assert len(shape.rows) == n - 1
    for r in shape.rows:
        assert r["r_d"] == pytest.approx(0.0, abs=1e-9) and r["r_phi"] == pytest.approx(
            0.0, abs=1e-9
        )


def test_a_child_on_the_wrong_side_fails_where_the_old_pair_check_passed() -> None:
    # leader 1 facing north; robot 2 is the LEFT child, robot 3 the RIGHT one, but they
    # stand swapped: 2 behind-right, 3 behind-left, each at d_e and φ_e
    final = pyramid(3, math.pi / 2)
    final[2], final[3] = final[3], final[2]
    links = [Link(2, 1, D, LEFT_CHILD), Link(3, 1, D, RIGHT_CHILD)]
    assert [lk.side for lk in links] == ["left", "right"]
    shape = check_shape(final, 1, links, PHI)
    assert not shape.ok
    for r in shape.rows:
        assert r["distance"] == pytest.approx(D)
        assert r["angle_deg"] == pytest.approx(-30.0)  # on the other side
        assert r["r_phi"] == pytest.approx(-2.0)
    # the old check (an unsigned angle off the axis) cannot tell left from right
    old = evaluate(final, [(2, 1), (3, 1)], math.pi / 2, D, PHI)
    assert all(abs(r["r_phi"]) < 1e-9 and abs(r["r_d"]) < 1e-9 for r in old)
    # matched from the truth alone, the two robots simply hold each other's slots
    assert judge_shape(final, [1, 2, 3], D, PHI).ok


def test_a_mirrored_partial_layer_is_no_pyramid() -> None:
    # 4 robots: the fourth belongs behind-left of the left child (eq. 7: a partial layer is
    # left-aligned); here it stands behind-right of the right child
    final = pyramid(4, math.pi / 2)
    x, y, h = final[3]
    final[4] = (x + D * math.sin(PHI), y - D * math.cos(PHI), h)
    assert not judge_shape(final, [1, 2, 3, 4], D, PHI).ok


def test_a_pyramid_built_facing_backwards_has_its_leader_behind() -> None:
    final = {i: (x, y, -math.pi / 2) for i, (x, y, _) in pyramid(3, math.pi / 2).items()}
    links = [Link(2, 1, D, LEFT_CHILD), Link(3, 1, D, RIGHT_CHILD)]
    shape = check_shape(final, 1, links, PHI)
    assert not shape.leader_in_front and not shape.ok
    assert not judge_shape(final, [1, 2, 3], D, PHI).ok


def test_distance_errors_and_missing_robots() -> None:
    final = pyramid(3, math.pi / 2)
    final[3] = (1.2 * final[3][0], 1.2 * final[3][1], final[3][2])  # 0.96 m: r_d +20 %
    shape = judge_shape(final, [1, 2, 3], D, PHI)
    assert not shape.ok
    assert max(r["r_d"] for r in shape.rows) == pytest.approx(0.2)
    gone = judge_shape({1: final[1], 2: final[2]}, [1, 2, 3], D, PHI)
    assert gone.missing == [3] and not gone.ok
    with pytest.raises(ValueError, match="no members"):
        judge_shape(final, [], D, PHI)


def test_excursions_from_the_reference_sample_on() -> None:
    truth = [
        (0.0, {1: (0.0, 0.0, 0.0), 2: (5.0, 0.0, 0.0)}),
        (1.0, {1: (2.0, 0.0, 0.0), 2: (5.0, 0.0, 1.0)}),  # 1 explores, 2 turns on the spot
        (2.0, {1: (2.0, 0.0, 0.0), 2: (5.0, 0.0, 2.0)}),  # 1's last record arrives here
        (3.0, {1: (2.0, 0.3, 0.0), 2: (5.0, 0.0, 2.0)}),
        (4.0, {1: (2.0, 0.1, 0.0), 2: (5.0, 0.0, 2.0)}),
    ]
    far = excursions(truth, [1, 2, 3], {1: 2})
    assert far == {1: pytest.approx(0.3), 2: 0.0}  # the farthest, not the final; 3: no pose
    assert excursions(truth, [1], {})[1] == pytest.approx(math.hypot(2.0, 0.3))
    assert excursions([], [1], {1: 4}) == {}


def test_settled_at_the_last_move_farther_than_2_cm_from_the_end() -> None:
    truth = [
        (0.0, {1: (0.0, 0.0, 0.0), 2: (5.0, 0.0, 0.0)}),
        (1.0, {1: (1.0, 0.0, 0.0), 2: (5.0, 0.0, 0.0)}),
        (2.0, {1: (1.99, 0.0, 0.0), 2: (5.0, 0.5, 0.0)}),  # 2 still 0.5 m off its end
        (3.0, {1: (2.0, 0.0, 0.0), 2: (5.0, 0.01, 0.0)}),  # both within 2 cm from here
        (4.0, {1: (2.0, 0.0, 1.0), 2: (5.0, 0.0, 0.0)}),  # 1 turns on the spot
    ]
    assert settled_at(truth, [1, 2]) == 3.0
    assert settled_at(truth, [1]) == 2.0
    assert settled_at(truth[:1], [1, 2]) == 0.0  # nobody moved
    assert math.isnan(settled_at([], [1]))


@pytest.mark.parametrize("name", sorted(BUILTIN))
@pytest.mark.parametrize("n", [2, 5, 9])
def test_every_built_in_shape_is_judged_right_wherever_it_faces(name: str, n: int) -> None:
    shape = BUILTIN[name]
    ids = list(range(1, n + 1))
    for facing in (math.pi / 2, -2.0):
        final = placed(shape.slots(n, D, PHI).positions, facing, (1.0, 3.0))
        verdict = judge_shape(final, ids, D, PHI, shape)
        assert verdict.ok and verdict.leader == 1 and len(verdict.rows) == n - 1, verdict
        for r in verdict.rows:
            assert r["r_d"] == pytest.approx(0.0, abs=1e-9)
            assert r["r_phi"] == pytest.approx(0.0, abs=1e-9)
        if name != "pyramid":  # the same robots are no pyramid
            assert not judge_shape(final, ids, D, PHI).ok


@pytest.mark.parametrize("name", ["line", "wedge", "circle", "grid", "column"])
def test_a_child_off_its_tree_offset_fails(name: str) -> None:
    shape = BUILTIN[name]
    slots = shape.slots(6, D, PHI).positions.copy()
    parent = shape.slots(6, D, PHI).edge(5)[0]
    # slot 5 turned by 15° about its parent: r_φ = ±50 % (over φ_e = 30°), r_d 0
    turn = math.radians(15.0)
    rel = slots[5] - slots[parent]
    c, s = math.cos(turn), math.sin(turn)
    slots[5] = slots[parent] + np.array([c * rel[0] - s * rel[1], s * rel[0] + c * rel[1]])
    verdict = judge_shape(placed(slots, 0.4), list(range(1, 7)), D, PHI, shape)
    assert not verdict.ok
    (row,) = [r for r in verdict.rows if r["child"] == 6]
    assert abs(row["r_phi"]) == pytest.approx(0.5) and row["r_d"] == pytest.approx(0.0, abs=1e-9)


def test_the_leader_in_front_only_of_the_robots_behind_it() -> None:
    # a line: nobody is behind the leader, so a line judged from its slots has no front
    line = BUILTIN["line"]
    final = placed(line.slots(5, D, PHI).positions, math.pi / 2)
    assert judge_shape(final, [1, 2, 3, 4, 5], D, PHI, line).leader_in_front
    # a wedge with its robots turned round: the apex is behind the arms
    wedge = BUILTIN["wedge"]
    ahead = placed(wedge.slots(5, D, PHI).positions, math.pi / 2)
    turned = {i: (x, y, -math.pi / 2) for i, (x, y, _) in ahead.items()}
    verdict = judge_shape(turned, [1, 2, 3, 4, 5], D, PHI, wedge)
    assert not verdict.leader_in_front and not verdict.ok


def test_a_formation_file_s_tree_is_judged_by_its_own_offsets() -> None:
    # leader, one robot 1 m to its left, one 0.6 m behind that one
    tree = Shape("L", "tree", ((0, 1.0, math.pi / 2), (1, 0.6, math.pi)))
    final = {1: (0.0, 0.0, 0.0), 2: (0.0, 1.0, 0.0), 3: (-0.6, 1.0, 0.0)}  # facing +x
    verdict = judge_shape(final, [1, 2, 3], D, PHI, tree)
    assert verdict.ok
    assert [(r["child"], r["parent"], r["side"]) for r in verdict.rows] == [
        (2, 1, "left"),
        (3, 2, "on axis"),
    ]
    assert [r["angle_deg"] for r in verdict.rows] == pytest.approx([90.0, 0.0])
    final[3] = (-0.6, 1.2, 0.0)  # 0.2 m to the left of its place: r_φ −61 %, r_d +5 %
    bad = judge_shape(final, [1, 2, 3], D, PHI, tree)
    assert not bad.ok
    assert bad.rows[1]["r_d"] == pytest.approx(math.hypot(0.6, 0.2) / 0.6 - 1.0)
