"""The half turn from the sweeps' overlapping views (agent/core/perception/half_turn.py)."""

from __future__ import annotations

import math
import random

import pytest
from hypothesis import given
from hypothesis import strategies as st

from agent.config import SEARCH_YAWS
from agent.core.perception.half_turn import half_turn, overlap_pairs

D = math.radians


def test_the_search_yaws_give_six_pairs_five_point_nine_degrees_apart() -> None:
    # ten yaws over ±119.5°, 26.56° apart: after the half turn, the head at -119.5° looks
    # at 60.5°, which the head at +66.4° saw (5.9° off); -92.9° -> 87.1° ~ +92.9°;
    # -66.4° -> 113.6° ~ +119.5°; and the mirror images.
    assert len(SEARCH_YAWS) == 10
    pairs = overlap_pairs(SEARCH_YAWS)
    assert pairs == ((7, 0), (8, 1), (9, 2), (0, 7), (1, 8), (2, 9))
    for i, j in pairs:
        gap = math.pi + SEARCH_YAWS[j] - SEARCH_YAWS[i]
        gap = (gap + math.pi) % (2 * math.pi) - math.pi
        assert abs(gap) == pytest.approx(D(5.9), abs=D(0.1))


def test_yaws_that_never_look_the_same_way_give_no_pair() -> None:
    assert overlap_pairs((-D(40), 0.0, D(40))) == ()


def test_a_tie_goes_to_the_smaller_index() -> None:
    # after the turn, -170° and +170° look at ±10°, both 10° off the view at 0°; and
    # 0° looks at 180°, which -170° and +170° (indices 0 and 1) both miss by 10°
    pairs = overlap_pairs((-D(170), D(170), 0.0), max_offset=D(10) + 1e-12)
    assert pairs == ((2, 0), (2, 1), (0, 2))


def test_half_turn_known_answer() -> None:
    # the body turned 178°: the before-view at +66.4° and after-view at -119.5° are
    # 178 - 119.5 - 66.4 = -7.9° apart as views; the compass sees exactly that.
    t = D(178.0)
    ms = [(D(66.4), -D(119.5), t - D(119.5) - D(66.4)), (D(92.9), -D(92.9), t - D(185.8))]
    assert half_turn(ms, turned=D(175.0)) == pytest.approx(t, abs=1e-12)


def test_half_turn_is_the_median_of_agreeing_views() -> None:
    t = D(181.0)
    good = [(0.0, math.pi, t - math.pi + e) for e in (D(0.1), -D(0.1), 0.0)]
    wrong = [(0.0, math.pi, t - math.pi + D(5))]  # a mismatch, outvoted
    assert half_turn(good + wrong, turned=D(180)) == pytest.approx(t + D(0.05), abs=1e-12)


def test_half_turn_needs_two_agreeing_views() -> None:
    assert half_turn([], turned=math.pi) is None
    assert half_turn([(0.0, math.pi, 0.01)], turned=math.pi) is None
    spread = [(0.0, math.pi, 0.0), (0.0, math.pi, D(3)), (0.0, math.pi, D(6))]
    assert half_turn(spread, turned=math.pi) is None


def test_half_turn_unwraps_next_to_the_believed_turn() -> None:
    # a believed turn of -179° and a true one of +179° (mod 2π the same as -181°)
    ms = [(0.0, 0.0, D(179.0))] * 2
    assert half_turn(ms, turned=-D(179.0)) == pytest.approx(-D(181.0), abs=1e-12)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"yaws": (0.0, math.nan)}, "finite"),
        ({"yaws": (0.0,), "turn": math.inf}, "finite"),
        ({"yaws": (0.0,), "max_offset": 0.0}, "max_offset"),
        ({"yaws": (0.0,), "max_offset": 1.0}, "max_offset"),
    ],
)
def test_overlap_pairs_errors(kwargs: dict[str, object], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        overlap_pairs(**kwargs)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("ms", "kwargs", "match"),
    [
        ([], {"turned": math.nan}, "turned"),
        ([], {"turned": 1.0, "agree": 0.0}, "agree"),
        ([], {"turned": 1.0, "agree": math.inf}, "agree"),
        ([], {"turned": 1.0, "min_agreeing": 0}, "min_agreeing"),
        ([(0.0, math.nan, 0.0)], {"turned": 1.0}, "not finite"),
    ],
)
def test_half_turn_errors(
    ms: list[tuple[float, float, float]], kwargs: dict[str, float], match: str
) -> None:
    with pytest.raises(ValueError, match=match):
        half_turn(ms, **kwargs)


@given(
    turn=st.floats(min_value=D(165), max_value=D(195)),
    believed=st.floats(min_value=-D(8), max_value=D(8)),
    seed=st.integers(0, 2**32 - 1),
)
def test_exact_views_give_the_true_turn_in_any_order(
    turn: float, believed: float, seed: int
) -> None:
    """Whatever the true turn near π, views the compass measures exactly give it back,
    from the search's own pairs, in any order of the measurements."""
    ms = []
    for i, j in overlap_pairs(SEARCH_YAWS):
        view = turn + SEARCH_YAWS[j] - SEARCH_YAWS[i]
        ms.append((SEARCH_YAWS[i], SEARCH_YAWS[j], (view + math.pi) % (2 * math.pi) - math.pi))
    random.Random(seed).shuffle(ms)
    got = half_turn(ms, turned=turn + believed)
    assert got is not None
    assert got == pytest.approx(turn, abs=1e-9)
