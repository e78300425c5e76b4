"""tools/harness/report.py: the runs JSON, the outcome counts, the table and the figure that
every evaluation tool shares."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tools.harness import report

ROWS = [
    {"seed": 1, "loss": 0.3, "outcome": "complete", "contacts": 0, "wall_s": 61.4, "detail": "ok"},
    {"seed": 2, "loss": 0.3, "outcome": "unsafe", "contacts": 2, "wall_s": 70.0, "detail": "x"},
    {"seed": 1, "loss": 0.0, "outcome": "safe_abort", "contacts": 0, "wall_s": 9.0, "detail": "y"},
]


def test_runs_json_round_trip(tmp_path: Path) -> None:
    a, b = tmp_path / "a.json", tmp_path / "deeper" / "b.json"
    report.write_runs(ROWS, a, None, b)
    assert json.loads(a.read_text()) == {"runs": ROWS} == json.loads(b.read_text())
    assert report.read_runs([a, b]) == ROWS + ROWS


def test_counts_per_group_in_order_of_appearance() -> None:
    counts = report.count_outcomes(ROWS, "loss")
    assert list(counts) == ["0.3", "0"]
    assert counts["0.3"] == {"complete": 1, "unsafe": 1} and counts["0"] == {"safe_abort": 1}
    only = report.count_outcomes(ROWS, "loss", lambda r: r["seed"] == 1, name=str)
    assert only == {"0.3": {"complete": 1}, "0.0": {"safe_abort": 1}}
    assert report.label(0.1) == "0.1" and report.label("kill-agent@move") == "kill-agent@move"


def test_table_has_a_line_per_run(capsys: pytest.CaptureFixture[str]) -> None:
    report.print_runs(ROWS, "loss", detail_width=1)
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0].split() == ["loss", "seed", "outcome", "contacts", "wall", "(s)", "detail"]
    assert lines[1].split() == ["0.3", "1", "complete", "0", "61", "o"]
    assert len(lines) == 1 + len(ROWS)


def test_figure(tmp_path: Path) -> None:
    report.plot_outcomes(report.count_outcomes(ROWS, "loss"), tmp_path / "o.png", "t", ylabel="y")
    assert (tmp_path / "o.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
