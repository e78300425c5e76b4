"""tools.eval_research: argument errors and the figure (the runs are the system tests')."""

from __future__ import annotations

from pathlib import Path

import pytest

from tools import eval_research


@pytest.mark.parametrize("seeds", ["x", ",", "1,b"])
def test_bad_seeds_are_usage_errors(seeds: str) -> None:
    with pytest.raises(SystemExit) as exc:
        eval_research.main(["--seeds", seeds])
    assert exc.value.code == 2


def test_plot_draws_one_bar_per_seed(tmp_path: Path) -> None:
    rows = [
        {"seed": 1, "success": True, "wall_total": 110.0, "wall_explore": 45.0},
        {"seed": 2, "success": False, "wall_total": 95.0, "wall_explore": 40.0},
    ]
    eval_research.plot(rows, tmp_path / "r.png", "research_found: 1/2 succeeded")
    assert (tmp_path / "r.png").read_bytes()[:4] == b"\x89PNG"
