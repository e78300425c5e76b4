"""``python -m tools.montecarlo``: a tiny real run (3 runs) and its JSON and figures."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_tiny_run_json_and_figures(tmp_path: Path) -> None:
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "tools.montecarlo",
            "--runs",
            "3",
            "--levels",
            "none,paper",
            "--strategies",
            "paper,default",
            "--json",
            "--out",
            str(tmp_path),
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
    res = doc["results"]
    assert set(res) == {
        f"{lv}/{s}/{f}"
        for lv in ("none", "paper")
        for s in ("paper", "default")
        for f in ("bfs", "lsq")
    }
    # without noise the pyramid is exact and every plan is safe
    for key, r in res.items():
        assert r["failures"] == 0
        assert r["planned_violations_per_run"] == 0
        if key.startswith("none/"):
            assert r["r_d_within_20pct"] == 1.0 and r["r_phi_within_30pct"] == 1.0
    assert res["none/default/lsq"]["path_over_optimum"] <= 1.05  # PATH_SLACK
    for r in res.values():
        assert 0 < r["makespan_over_capt"] <= r["wave_makespan_over_capt"]
    for name in ("fig15_histograms.png", "fig16_fleets.png", "fig17_obstacles.png"):
        assert (tmp_path / name).stat().st_size > 5000


def test_bad_option_exit_2() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "tools.montecarlo", "--levels", "huge"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=60,
    )
    assert out.returncode == 2 and "huge" in out.stderr
