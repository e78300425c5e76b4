"""tools.eval_loss: the verdict of a run and the per-loss summary, on hand-made results."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from tools import eval_loss
from tools.eval_loss import RunResult, _fmt, _reason, summarise


def _ok_result() -> dict[str, object]:
    return {
        "exit_codes": {"1": 0, "2": 0, "3": 0},
        "final_phase": {"1": "done", "2": "done", "3": "done"},
        "identical_digests": True,
        "contacts": 0,
        "within_tolerance": True,
        "max_abs_r_d": 0.05,
        "max_abs_r_phi": 0.1,
    }


def _run(loss: float, ok: bool, agree: float | None, nbytes: list[int]) -> RunResult:
    return RunResult(
        loss=loss, seed=1, robots=len(nbytes), success=ok, reason="ok" if ok else "x",
        agree_s=agree, wall_s=10.0, bytes_per_agent=nbytes,
        exchange_bytes_per_agent=[b // 2 for b in nbytes], exit_codes=[0] * len(nbytes),
        phases=["done"] * len(nbytes), same_plan=ok, contacts=0, max_abs_r_d=0.0,
        max_abs_r_phi=0.0, dropped_packets=10, out="",
    )  # fmt: skip


def test_reason_ok() -> None:
    assert _reason(_ok_result(), 3) == "ok"


def test_reason_each_failure() -> None:
    r = _ok_result()
    r["timeout"] = "agents still running after 9 s"
    assert _reason(r, 3) == "agents still running after 9 s"
    r = _ok_result()
    r["exit_codes"] = {"1": 0, "2": 1, "3": 0}
    r["errors"] = {"2": "no agreement"}
    assert _reason(r, 3) == "agent exit codes [0, 1, 0]: no agreement"
    assert _reason(_ok_result(), 4).startswith("agent exit codes")  # one agent missing
    r = _ok_result()
    r["final_phase"] = {"1": "done", "2": "hold", "3": "done"}
    assert _reason(r, 3).startswith("final phases")
    r = _ok_result()
    r["identical_digests"] = False
    assert _reason(r, 3) == "plan digests differ"
    r = _ok_result()
    r["contacts"] = 2
    assert _reason(r, 3) == "2 contacts"
    r = _ok_result()
    r["within_tolerance"] = False
    assert _reason(r, 3) == "outside tolerance: max|r_d| 5.0%, max|r_phi| 10.0%"


def test_summarise_known_answer() -> None:
    rows = summarise(
        [
            _run(0.3, True, 4.0, [1000, 2000]),
            _run(0.0, True, 1.0, [500, 500]),
            _run(0.3, False, None, [3000, 2000]),
            _run(0.0, True, 3.0, [500, 500]),
        ]
    )
    assert [r["loss"] for r in rows] == [0.0, 0.3]
    assert rows[0]["success_rate"] == 1.0 and rows[1]["success_rate"] == 0.5
    assert rows[0]["agree_s_mean"] == 2.0 and rows[0]["agree_s_max"] == 3.0
    assert rows[1]["agree_s_mean"] == 4.0  # the failed run has no agreement time
    assert rows[1]["bytes_per_agent_mean"] == 2000.0
    assert rows[1]["exchange_bytes_per_agent_mean"] == 1000.0
    assert rows[0]["dropped_packets_mean"] == 10.0


def test_plot_writes_png(tmp_path: Path) -> None:
    rows = summarise([_run(0.0, True, 1.0, [500]), _run(0.1, False, None, [900])])
    eval_loss.plot(rows, tmp_path / "loss.png")
    assert (tmp_path / "loss.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_fmt_pads_missing_values() -> None:
    assert _fmt(None, "8.1f") == "       -"
    assert _fmt(2.25, "8.1f") == "     2.2"
    assert _fmt(math.pi, ".2f") == "3.14"


@pytest.mark.parametrize(
    ("argv", "msg"),
    [
        (["--loss", "a,b"], "comma-separated"),
        (["--loss", "0,1.5"], "probability"),
        (["--robots", "0"], "--robots"),
        (["--seeds", "0"], "--seeds"),
    ],
)
def test_cli_rejects_bad_arguments(
    argv: list[str], msg: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert eval_loss.main(argv) == 2
    assert msg in capsys.readouterr().err
