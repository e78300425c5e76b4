"""``python -m tools.plan``: the CLI contract with real processes."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from agent.core.formation.params import D_E

ROOT = Path(__file__).resolve().parents[2]


def run(doc: object, *args: str, raw: str | None = None) -> subprocess.CompletedProcess[str]:
    text = raw if raw is not None else json.dumps(doc)
    return subprocess.run(
        [sys.executable, "-m", "tools.plan", *args],
        input=text,
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )


def test_plan_roundtrip_and_png(tmp_path: Path) -> None:
    doc = {
        "robots": [
            {"id": 7, "x": 0.1, "y": 2.0},
            {"id": 3, "x": 1.0, "y": 1.2},
            {"id": 9, "x": -0.8, "y": 1.5},
        ],
        "d_e": D_E,
        "phi_e_deg": 30,
        "strategy": "paper",
    }
    png = tmp_path / "plan.png"
    out = run(doc, "--png", str(png))
    assert out.returncode == 0, out.stderr
    plan = json.loads(out.stdout)
    assert set(plan) == {
        "leader",
        "axis_rad",
        "targets",
        "trajectories",
        "waves",
        "digest",
        "strategy",
    }
    assert plan["leader"] in plan["waves"][0]
    wave = {i: k for k, w in enumerate(plan["waves"]) for i in w}
    for tr in plan["trajectories"]:  # a robot waits only for robots of earlier waves
        assert tr["wave"] == wave[tr["id"]]
        assert all(wave[j] < wave[tr["id"]] for j in tr["after"])
    assert sorted(t["id"] for t in plan["targets"]) == [3, 7, 9]
    assert sorted(t["order"] for t in plan["targets"]) == [0, 1, 2]
    by_id = {t["id"]: t for t in plan["targets"]}
    for t in plan["targets"]:
        if t["parent"] >= 0:
            p = by_id[t["parent"]]
            assert np.hypot(t["x"] - p["x"], t["y"] - p["y"]) == pytest.approx(D_E)
    for tr in plan["trajectories"]:
        start = next(r for r in doc["robots"] if r["id"] == tr["id"])
        end = tr["via"][0] if tr["via"] else [by_id[tr["id"]]["x"], by_id[tr["id"]]["y"]]
        assert np.hypot(end[0] - start["x"], end[1] - start["y"]) == pytest.approx(tr["distance"])
    assert png.stat().st_size > 1000
    # shuffled input -> identical digest
    doc2 = dict(doc, robots=list(reversed(doc["robots"])))
    assert json.loads(run(doc2).stdout)["digest"] == plan["digest"]


def test_thousand_robots_and_obstacles() -> None:
    rng = np.random.default_rng(0)
    g = np.stack(np.meshgrid(np.arange(25), np.arange(40)), -1).reshape(-1, 2) * 2.0
    pts = g + rng.uniform(-0.3, 0.3, g.shape)
    doc = {
        "robots": [{"id": i, "x": float(x), "y": float(y)} for i, (x, y) in enumerate(pts)],
        "d_e": 2.0,
    }
    out = run(doc)
    assert out.returncode == 0, out.stderr
    assert len(json.loads(out.stdout)["targets"]) == 1000
    doc = {
        "robots": [{"id": i, "x": float(i % 3), "y": float(i // 3)} for i in range(6)],
        "obstacles": [{"x": 1.0, "y": 2.5}],
        "d_e": 1.0,
    }
    out = run(doc)
    assert out.returncode == 0, out.stderr


@pytest.mark.parametrize(
    ("doc", "raw", "msg"),
    [
        (None, "{not json", "invalid JSON"),
        ([], None, "JSON object"),
        ({"robots": [{"id": 1, "x": 0, "y": 0}]}, None, "missing 'd_e'"),
        ({"robots": [], "d_e": 1}, None, "non-empty"),
        ({"robots": [{"id": 1, "x": 0}], "d_e": 1}, None, "missing 'y'"),
        ({"robots": [{"id": -1, "x": 0, "y": 0}], "d_e": 1}, None, "non-negative integer"),
        ({"robots": [{"id": 1, "x": "a", "y": 0}], "d_e": 1}, None, "finite number"),
        (
            {"robots": [{"id": 1, "x": 0, "y": 0}, {"id": 1, "x": 1, "y": 0}], "d_e": 1},
            None,
            "duplicate",
        ),
        ({"robots": [{"id": 1, "x": 0, "y": 0}], "d_e": -1}, None, "d_e"),
        ({"robots": [{"id": 1, "x": 0, "y": 0}], "d_e": 1, "strategy": "fast"}, None, "strategy"),
        ({"robots": [{"id": 1, "x": 0, "y": 0}], "d_e": 1, "orientation": 3}, None, "orientation"),
        ({"robots": [{"id": 1, "x": 0, "y": 0}], "d_e": 1, "colour": "red"}, None, "unknown keys"),
        ({"robots": [{"id": 1, "x": 0, "y": 0}], "d_e": 1, "obstacles": [3]}, None, "obstacles"),
        ({"robots": ["x"], "d_e": 1}, None, "object with id"),
    ],
)
def test_bad_input_exit_2_one_line(doc: object, raw: str | None, msg: str) -> None:
    out = run(doc, raw=raw)
    assert out.returncode == 2
    assert out.stdout == ""
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and msg in lines[0], out.stderr


def test_bench_plan_prints_the_table_and_draws(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from tools.bench.plan import all_fleets, main

    png = tmp_path / "bench.png"
    args = ["--sizes", "10,40", "--no-cli", "--stuck-n", "0", "--no-families", "--png", str(png)]
    assert main(args) == 0
    out = capsys.readouterr().out
    for head in ("plan s", "ms/capt", "waves", "path/opt", "growth exponent"):
        assert head in out
    assert png.stat().st_size > 5000
    fleets = all_fleets()
    assert len(fleets) == 67 and {f[0] for f in fleets} == {
        "nao",
        "uniform",
        "blobs",
        "line",
        "ring",
        "grid",
    }
    assert main(["--sizes", "ten"]) == 2
