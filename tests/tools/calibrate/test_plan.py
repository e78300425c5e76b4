"""The plan: the paper's views, grouped by placement, NAO-j turning left from facing NAO-i,
held-out views that keep NAO-j whole in the image."""

from __future__ import annotations

import math
from collections import Counter

import pytest
from hypothesis import given
from hypothesis import strategies as st

from agent.core.perception.camera import CameraModel
from tools.calibrate import __main__ as cli
from tools.calibrate.plan import FACING_DEG, HALF_WIDTH, PlanSpec, coarse, turning_order


def test_the_papers_grid() -> None:
    shots = PlanSpec().shots()
    kinds = Counter((s.set, s.kind) for s in shots)
    assert kinds[("mbase", "main")] == 72 and kinds[("mbase", "head")] == 48
    assert kinds[("mbase", "side")] == 4
    assert {s.distance for s in shots if s.set == "dbase"} == set(PlanSpec().distances) - {0.6}
    assert len({s.id for s in shots}) == len(shots)
    # one prompt per placement: a placement's views come together
    seen: list[tuple[str, float, float]] = []
    for s in shots:
        if not seen or seen[-1] != s.placement:
            assert s.placement not in seen
            seen.append(s.placement)


def test_side_views_look_where_nao_j_stands() -> None:
    for s in PlanSpec().shots():
        if s.kind == "side":
            assert s.observer_yaw_deg == s.bearing_deg and abs(s.bearing_deg) == 90.0


@given(st.lists(st.floats(0.0, 359.9), min_size=1, max_size=20, unique=True))
def test_nao_j_turns_left_from_facing_nao_i(orients: list[float]) -> None:
    order = turning_order(orients)
    gone = [(o - FACING_DEG) % 360.0 for o in order]
    assert gone == sorted(gone) and sorted(order) == sorted(orients)


def test_held_out_views_keep_nao_j_whole_in_the_image() -> None:
    cam = CameraModel()
    checks = [s for s in PlanSpec().shots() if s.set == "check" and s.kind == "main"]
    assert {s.observer_yaw_deg for s in checks} - {0.0}  # NAO-j off the image centre too
    for s in checks:
        edge = math.radians(abs(s.observer_yaw_deg)) + math.atan(HALF_WIDTH / s.distance)
        assert edge < cam.hfov / 2
    assert sum(s.kind == "none" for s in PlanSpec().shots()) == PlanSpec().negatives


def test_the_spec_round_trips_and_coarse_is_small() -> None:
    for spec in (PlanSpec(), coarse()):
        assert PlanSpec.from_dict(spec.to_dict()) == spec
    assert len(coarse().shots()) < 100


@pytest.mark.parametrize(
    ("kwargs", "why"),
    [
        ({"step_deg": 7.0}, "divide 360"),
        ({"distances": (0.5, 0.6)}, "3 distinct"),
        ({"distances": (0.5, 0.6, 5.0)}, "outside"),
        ({"d_s": 3.0}, "d_s"),
        ({"head_yaws_deg": (130.0,)}, "119.5"),
        ({"negatives": -1}, "negatives"),
    ],
)
def test_a_bad_grid_says_why(kwargs: dict[str, object], why: str) -> None:
    with pytest.raises(ValueError, match=why):
        PlanSpec(**kwargs)  # type: ignore[arg-type]


def test_unknown_fields_in_a_stored_plan() -> None:
    with pytest.raises(ValueError, match="unknown plan fields"):
        PlanSpec.from_dict({"step": 5})


def test_grid_options_of_the_command_line() -> None:
    args = cli.parser().parse_args(
        ["capture", "--observer", "tcp://a:9559", "--subject", "tcp://b:9559", "--out", "x",
         "--grid", "quick", "--distances", "0.5,1,2", "--step", "10"]
    )  # fmt: skip
    spec = cli.grid(args)
    assert spec.dbase_step_deg == 15.0 and spec.distances == (0.5, 1.0, 2.0)
    assert spec.step_deg == 10.0 and not spec.dbase_poses
