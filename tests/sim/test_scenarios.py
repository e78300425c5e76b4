"""Scenario generation, files and validation (sim/scenarios)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from agent.core.perception import SIGHT_MAX, SIGHT_MIN
from sim import scenarios
from sim.scenarios import (
    DETECT_MAX,
    DETECT_MIN,
    ISOLATED_MIN,
    ClutterSpec,
    LightSpec,
    ObstacleSpec,
    RobotSpec,
    Scenario,
    builtin,
    dump,
    generate,
    load,
)


def _connected(pts: np.ndarray, lo: float, hi: float) -> bool:
    n = len(pts)
    d = np.linalg.norm(pts[:, None] - pts[None], axis=2)
    adj = (d >= lo) & (d <= hi)
    seen, stack = {0}, [0]
    while stack:
        i = stack.pop()
        for j in np.flatnonzero(adj[i]):
            if int(j) not in seen:
                seen.add(int(j))
                stack.append(int(j))
    return len(seen) == n


@pytest.mark.parametrize("n", [1, 2, 3, 5, 10, 15, 50])
@pytest.mark.parametrize("seed", [0, 1, 7])
def test_generated_starts_are_paper_like(n: int, seed: int) -> None:
    sc = generate(n, seed)
    assert [r.id for r in sc.robots] == list(range(1, n + 1))
    assert all(r.heading == math.pi / 2 for r in sc.robots)
    pts = np.array([(r.x, r.y) for r in sc.robots])
    if n > 1:
        d = np.linalg.norm(pts[:, None] - pts[None], axis=2)
        np.fill_diagonal(d, np.inf)
        assert d.min() >= 0.6 - 1e-3  # rounding to mm
        nearest = d.min(axis=1)
        assert np.all(nearest <= 1.2 + 1e-3)
        assert np.all((nearest >= DETECT_MIN) & (nearest <= DETECT_MAX))
        assert _connected(pts, DETECT_MIN, DETECT_MAX)
        assert _connected(pts, 0.5, 1.45)  # the paper's range too: spacing 0.6-1.2 m
    assert np.abs(pts).max() <= sc.room - 1.5


def test_detection_range_is_perceptions() -> None:
    assert (DETECT_MIN, DETECT_MAX) == (SIGHT_MIN, SIGHT_MAX) == (0.5, 3.0)


@pytest.mark.parametrize("n", [2, 3, 4, 6, 10])
@pytest.mark.parametrize("seed", range(6))
def test_isolated_robot_is_2_to_3_m_from_everyone(n: int, seed: int) -> None:
    sc = generate(n, seed, isolated=True)
    pts = np.array([(r.x, r.y) for r in sc.robots])
    d = np.linalg.norm(pts[:, None] - pts[None], axis=2)
    np.fill_diagonal(d, np.inf)
    lone = d[-1]  # robot n
    assert ISOLATED_MIN - 1e-3 <= lone.min() <= DETECT_MAX + 1e-3
    assert _connected(pts, DETECT_MIN, DETECT_MAX)  # it still sees the fleet
    rest = generate(n - 1, seed)
    if n > 2:  # the others as generated without it (up to the centring)
        q = np.array([(r.x, r.y) for r in rest.robots])
        shift = pts[: n - 1] - q
        assert np.allclose(shift, shift[0], atol=2e-3)
    assert np.abs(pts).max() <= sc.room - 1.5
    assert sc == generate(n, seed, isolated=True)


def test_isolated_needs_two_robots() -> None:
    with pytest.raises(ValueError, match="at least 2 robots"):
        generate(1, 0, isolated=True)


def test_generate_is_deterministic_and_seeded() -> None:
    assert generate(8, 3) == generate(8, 3)
    assert generate(8, 3) != generate(8, 4)


def test_generated_obstacles_and_clutter_keep_clear_of_robots() -> None:
    sc = generate(5, 2, obstacles=3, clutter=4)
    assert len(sc.obstacles) == 3 and len(sc.clutter) == 4
    for item in (*sc.obstacles, *sc.clutter):
        for r in sc.robots:
            assert math.hypot(item.x - r.x, item.y - r.y) >= 0.8


def test_file_round_trip(tmp_path: Path) -> None:
    sc = generate(4, 9, obstacles=1, clutter=2, light=LightSpec(0.7, 1.0, 0.5))
    path = tmp_path / "s.json"
    dump(sc, path)
    assert load(path) == sc


def test_builtin_files_load() -> None:
    for name in ("paper3", "obstacles", "clutter"):
        sc = load(builtin(name))
        assert sc.robots
    with pytest.raises(ValueError, match="no built-in"):
        builtin("nope")


@pytest.mark.parametrize(
    ("kwargs", "reason"),
    [
        ({"robots": ()}, "no robots"),
        ({"robots": (RobotSpec(1, 0, 0), RobotSpec(1, 1, 0))}, "duplicate"),
        ({"robots": (RobotSpec(1, 0, 0),), "room": 0.5}, "room half-size"),
        ({"robots": (RobotSpec(-1, 0, 0),)}, "robot id"),
        ({"robots": (RobotSpec(1, math.nan, 0),)}, "not finite"),
        ({"robots": (RobotSpec(1, 3.9, 0),), "room": 4.0}, "outside the room"),
        ({"robots": (RobotSpec(1, 0, 0),), "obstacles": (ObstacleSpec(1, 1, 0.0),)}, "obstacle"),
        (
            {"robots": (RobotSpec(1, 0, 0),), "clutter": (ClutterSpec(1, 1, 0.1, 2.0),)},
            "clutter",
        ),
        ({"robots": (RobotSpec(1, 0, 0),), "light": LightSpec(intensity=-1)}, "light"),
        ({"robots": (RobotSpec(1, 0, 0), RobotSpec(2, 0.3, 0))}, "overlap"),
        ({"robots": (RobotSpec(1, 0, 0),), "obstacles": (ObstacleSpec(0.3, 0),)}, "overlaps robot"),
    ],
)
def test_invalid_scenarios(kwargs: dict[str, object], reason: str) -> None:
    with pytest.raises(ValueError, match=reason):
        Scenario(**kwargs)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("[1, 2]", "JSON object"),
        ('{"robots": [], "extra": 1}', "unknown scenario keys"),
        ('{"obstacles": []}', "missing"),
        ('{"robots": [{"id": 1, "x": 0}]}', "bad scenario entry"),
        ('{"robots": [{"id": 1, "x": 0, "y": 0}], "seed": "a"}', "seed"),
        ("{not json", "not JSON"),
    ],
)
def test_invalid_files(tmp_path: Path, text: str, reason: str) -> None:
    path = tmp_path / "bad.json"
    path.write_text(text)
    with pytest.raises(ValueError, match=reason):
        load(path)


@pytest.mark.parametrize(
    ("n", "obstacles", "reason"), [(0, 0, "robot count"), (201, 0, "robot count"), (3, -1, ">= 0")]
)
def test_invalid_generate(n: int, obstacles: int, reason: str) -> None:
    with pytest.raises(ValueError, match=reason):
        generate(n, 0, obstacles=obstacles)


def test_dump_is_plain_json(tmp_path: Path) -> None:
    path = tmp_path / "s.json"
    dump(generate(2, 1), path)
    data = json.loads(path.read_text())
    assert set(data) == {"robots", "obstacles", "clutter", "light", "seed", "room"}
    assert scenarios.from_dict(data) == generate(2, 1)


# ------------------------------------------- start headings: robots set down facing anywhere


@pytest.mark.parametrize(
    ("text", "kind", "spread"),
    [("aligned", "aligned", 0.0), ("random", "random", 0.0), ("jitter:20", "jitter", 20.0)],
)
def test_headings_parse(text: str, kind: str, spread: float) -> None:
    h = scenarios.Headings.parse(text)
    assert (h.kind, h.spread_deg) == (kind, spread)
    assert str(h) == text


@pytest.mark.parametrize("text", ["", "north", "jitter", "jitter:", "jitter:0", "jitter:-5",
                                  "jitter:181", "jitter:nan", "jitter:x", "random:3"])  # fmt: skip
def test_headings_parse_refuses(text: str) -> None:
    with pytest.raises(ValueError, match="headings"):
        scenarios.Headings.parse(text)


def test_headings_leave_the_positions_of_a_seed_alone() -> None:
    base = scenarios.generate(6, 11)
    for text in ("random", "jitter:20"):
        sc = scenarios.generate(6, 11, headings=scenarios.Headings.parse(text))
        assert [(r.id, r.x, r.y) for r in sc.robots] == [(r.id, r.x, r.y) for r in base.robots]
    assert all(r.heading == scenarios.NORTH for r in base.robots)


def test_jitter_stays_within_its_spread_and_random_covers_the_circle() -> None:
    jit = scenarios.Headings.parse("jitter:20").draw(200, 3)
    assert all(abs(h - scenarios.NORTH) <= math.radians(20) + 1e-6 for h in jit)
    rnd = scenarios.Headings.parse("random").draw(400, 3)
    assert all(-math.pi <= h <= math.pi for h in rnd)
    # every quarter of the circle gets robots
    assert {int((h + math.pi) // (math.pi / 2)) % 4 for h in rnd} == {0, 1, 2, 3}
    assert scenarios.Headings.parse("random").draw(5, 3) == scenarios.Headings.parse("random").draw(
        5, 3
    )


def test_random_headings_survive_the_file_round_trip(tmp_path: Path) -> None:
    sc = scenarios.generate(4, 2, headings=scenarios.Headings.parse("random"))
    scenarios.dump(sc, tmp_path / "s.json")
    assert scenarios.load(tmp_path / "s.json") == sc
