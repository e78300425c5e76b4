"""tools.eval_headings without runs: cases, report mode, table, figure; the progress line."""

from __future__ import annotations

import io
import json
from dataclasses import asdict
from pathlib import Path

import pytest

from tools.eval_headings import Case, Run, main, parse_args
from tools.harness.progress import Progress


def test_cases_are_the_product_of_headings_sizes_and_faults() -> None:
    a = parse_args(["--headings", "random", "--headings", "jitter:20", "--robots", "4",
                    "--robots", "6", "--sensor-fault", "rotate:40"])  # fmt: skip
    assert [c.name for c in a.cases] == [
        "random N=4 rotate:40", "random N=6 rotate:40",
        "jitter:20 N=4 rotate:40", "jitter:20 N=6 rotate:40",
    ]  # fmt: skip
    assert parse_args([]).cases[0].name == "random N=4"


def test_the_faulty_robot_turns_with_the_seed() -> None:
    c = parse_args(["--robots", "6", "--sensor-fault", "scale:1.4"]).cases[0]
    assert [c.victim(s) for s in (1, 2, 6, 7)] == [2, 3, 1, 2]
    assert Case(c.headings, 6).victim(3) == -1


@pytest.mark.parametrize(
    "argv",
    [["--headings", "sideways"], ["--robots", "1"], ["--seeds", "0"], ["--sensor-fault", "spin:3"]],
)
def test_bad_arguments(argv: list[str]) -> None:
    with pytest.raises(SystemExit):
        parse_args(argv)


def test_report_mode_writes_the_table_and_figure(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    runs = [
        Run("random N=4", 1, "complete", 0, 40.0, "done, pairs within tolerance", verdicts_agree=True),
        Run("random N=4", 2, "unsafe", 0, 41.0, "every agent said done on a wrong formation",
            silent_wrong=True),
        Run("aligned N=6 rotate:40", 1, "safe_abort", 0, 30.0, "stopped", fault="rotate:40",
            victim=2, named=[2], verdicts_agree=True),
    ]  # fmt: skip
    src = tmp_path / "in.json"
    src.write_text(json.dumps({"runs": [asdict(r) for r in runs]}))
    assert main(["--report", str(src), "--out", str(tmp_path / "out")]) == 0
    text = capsys.readouterr().out
    assert "random N=4" in text and "1/1" in text  # the faulty robot named right
    assert (tmp_path / "out" / "headings.png").stat().st_size > 1000
    assert json.loads((tmp_path / "out" / "results.json").read_text())["runs"][1]["silent_wrong"]


def test_progress_estimates_what_is_left() -> None:
    now = [0.0]
    out = io.StringIO()
    bar = Progress(4, "t", stream=out, clock=lambda: now[0])
    now[0] = 60.0
    bar.step("first")
    assert "1/4" in out.getvalue() and "about 3:00 left" in out.getvalue()
    assert "first" in out.getvalue()
    with pytest.raises(ValueError, match="total"):
        Progress(0, "t")
