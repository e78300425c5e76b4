"""tools/harness/truth.py: who moved and the pyramid's shape, from true poses alone (known
answers worked by hand)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agent.core.formation.params import D_E, PHI_E_DEG
from agent.core.formation.shape.pyramid import slot_positions
from tools.harness.judge import evaluate
from tools.harness.truth import (
    LEFT,
    RIGHT,
    Link,
    check_shape,
    excursions,
    judge_shape,
    slot_tree,
)

D, PHI = D_E, math.radians(PHI_E_DEG)


def pyramid(n: int, facing: float, origin: tuple[float, float] = (0.0, 0.0)) -> dict[int, tuple]:
    """Robots 1..n on the slots of a pyramid of n facing ``facing``, headings ``facing``."""
    fwd = np.array([math.cos(facing), math.sin(facing)])
    left = np.array([-fwd[1], fwd[0]])
    s = slot_positions(n, D, PHI)
    return {k + 1: (*(np.array(origin) + s[k, 1] * fwd - s[k, 0] * left), facing) for k in range(n)}


def test_the_slot_tree_is_the_pyramids_definition() -> None:
    assert slot_tree(6) == [(-1, 0), (0, LEFT), (0, RIGHT), (1, LEFT), (2, LEFT), (2, RIGHT)]
    # every side as the slots place it: a left child lies left (x smaller) of its parent
    s = slot_positions(10, D, PHI)
    for k, (p, side) in enumerate(slot_tree(10)[1:], start=1):
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
    links = [Link(2, 1, LEFT), Link(3, 1, RIGHT)]
    shape = check_shape(final, 1, links, D, PHI)
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
    links = [Link(2, 1, LEFT), Link(3, 1, RIGHT)]
    shape = check_shape(final, 1, links, D, PHI)
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
