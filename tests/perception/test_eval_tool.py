"""The evaluation tool as a user runs it: a real process printing one JSON object."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from agent.core.perception.calibration import builtin

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow  # the evaluation tool on rendered views: CI's slow tier
def test_eval_perception_json(tmp_path: Path) -> None:
    png = tmp_path / "eval.png"
    view = tmp_path / "view.png"
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "tools.eval_perception",
            "--seed",
            "3",
            "--views",
            "4",
            "--compass-samples",
            "1",
            "--compass-away",
            "3",
            "--json",
            "--png",
            str(png),
            "--view-png",
            str(view),
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr
    summary = json.loads(out.stdout)
    assert summary["views"] == 4 and summary["seed"] == 3
    assert summary["calibration"] == builtin().digest
    for key in ("recall", "precision", "distance_error_m", "bearing_error_deg", "compass"):
        assert key in summary
    assert summary["compass"]["featureless"]["ok"] is False
    away = summary["compass_away"]
    assert set(away) == {"0", "0.25", "0.5", "1", "1.5", "2"}
    assert away["0"]["failures"] == 0 and away["0"]["max_err_deg"] < 1.0  # in place: exact
    assert png.stat().st_size > 10_000 and view.stat().st_size > 10_000


@pytest.mark.parametrize("flag", ["--views=0", "--compass-away=-1"])
def test_eval_perception_rejects_bad_arguments(flag: str) -> None:
    out = subprocess.run(
        [sys.executable, "-m", "tools.eval_perception", flag],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 2 and flag.split("=")[0] in out.stderr


def test_eval_perception_names_a_bad_calibration_folder(tmp_path: Path) -> None:
    out = subprocess.run(
        [sys.executable, "-m", "tools.eval_perception", "--calibration", str(tmp_path)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 2 and f"{tmp_path / 'orange.json'}: missing" in out.stderr
