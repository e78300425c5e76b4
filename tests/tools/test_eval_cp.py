"""tools.eval_cp: the paper's relative errors by hand, the variants' fleets, the tables
(the runs themselves are fleets: tests/system/test_circle_pattern.py)."""

from __future__ import annotations

import math

import pytest

from tools.eval_cp import PAPER, VARIANTS, Run, relative_errors, spec_of, tables
from tools.harness.fleet import FleetSpec

D_E, PHI = 0.8, math.radians(30.0)


def test_relative_errors_known_answers() -> None:
    exact = {"distance": D_E, "angle_deg": 30.0}
    assert relative_errors([exact], D_E, PHI) == [[pytest.approx(0.0, abs=1e-12)] * 4]
    # 10 % too far, on the slot's bearing: x, y and distance all +10 %, angle 0
    far = relative_errors([{"distance": 0.88, "angle_deg": 30.0}], D_E, PHI)[0]
    assert far == pytest.approx([0.1, 0.1, 0.1, 0.0])
    # at d_e but 45° off the backward axis: x = d sin 45° against d sin 30°
    off = relative_errors([{"distance": D_E, "angle_deg": 45.0}], D_E, PHI)[0]
    want = [math.sin(math.radians(45)) / 0.5 - 1, math.cos(math.radians(45)) / math.cos(PHI) - 1,
            0.0, 0.5]  # fmt: skip
    assert off == pytest.approx(want)
    assert relative_errors([], D_E, PHI) == []


def test_each_variant_is_its_fleet() -> None:
    base = FleetSpec()
    pca, no_tune, tune = (spec_of(base, v, False) for v in VARIANTS)
    assert (pca.agent.orientation, pca.agent.correct) == ("pca", False)
    assert (no_tune.agent.orientation, no_tune.agent.cp_tune) == ("cp", False)
    assert (tune.agent.orientation, tune.agent.cp_tune) == ("cp", True)
    assert spec_of(base, "cp-tune", True).agent.correct is True
    assert "--no-cp-tune" in no_tune.agent.to_argv() and "--no-correct" in tune.agent.to_argv()
    with pytest.raises(ValueError, match="variant"):
        spec_of(base, "spiral", False)


def run(variant: str, n: int, errors: list[list[float]], build: float | None) -> Run:
    return Run(case=f"{variant} n={n}", seed=1, outcome="complete", contacts=0, wall_s=1.0,
               detail="", variant=variant, robots=n, errors=errors, build_s=build)  # fmt: skip


def test_tables_by_hand() -> None:
    runs = [
        run("cp-tune", 4, [[0.1, -0.1, 0.0, 0.2]], 100.0),
        run("cp-tune", 6, [[-0.3, 0.1, 0.0, -0.2]], 120.0),
        run("pca", 4, [], None),  # a run that built nothing
    ]
    rows = {(r["variant"], r["robots"]): r for r in tables(runs)}
    both = rows[("cp-tune", 0)]
    assert both["runs"] == 2 and both["pairs"] == 2 and both["complete"] == 2
    assert both["aver"] == pytest.approx([20.0, 10.0, 0.0, 20.0])
    assert both["stdev"] == pytest.approx([math.sqrt(0.08), math.sqrt(0.02), 0.0, math.sqrt(0.08)])
    assert both["time"] == pytest.approx([110.0, math.sqrt(200.0)])
    assert rows[("cp-tune", 4)]["stdev"] == [] and rows[("pca", 4)]["aver"] == []
    assert set(PAPER) == set(VARIANTS)
