"""tools.eval_scale (and its rows and report, tools.lib.scale_report) without runs: a judged
result as a row, the table, the phase chart and the report path, the load sampler, the
arguments, the spec of a run."""

from __future__ import annotations

import json
import threading
from dataclasses import asdict
from pathlib import Path
from typing import Any

import pytest

from tools.eval_scale import agree_timeout, load_samples, main, parse_args, run_one, wave_timeout
from tools.harness.fleet import MAX_ROBOTS, FleetSpec
from tools.lib.scale_report import PHASES, Run, markdown, plot_phases, row_of

PHASE_WALLS = {"start": 4.0, "search": 238.0, "localise": 2.0, "exchange": 46.0, "agree": 1.5,
               "plan": 0.5, "wait": 100.0, "move": 94.0, "hold": 124.0}  # fmt: skip


def result(**over: Any) -> dict[str, Any]:
    """A judged ``result.json`` of a complete 3-NAO run (the keys eval_scale reads)."""
    r: dict[str, Any] = {
        "contacts": 0,
        "wall_total": 454.0,
        "wall_world_ready": 21.0,
        "exit_codes": {"1": 0, "2": 0, "3": 0},
        "final_phase": {"1": "done", "2": "done", "3": "done"},
        "plan_digests": {"1": "ab", "2": "ab", "3": "ab"},
        "identical_digests": True,
        "within_tolerance": True,
        "exchange_bytes": {"1": 3000, "2": 1000, "3": 2000},
        "agreement_s": 4.25,
        "phases": {p: {"wall_max": w, "sim_max": w / 2} for p, w in PHASE_WALLS.items()},
        "max_abs_r_d": 0.05,
        "max_abs_r_phi": float("nan"),
        "min_separation": 0.52,
        "silent_wrong": False,
        "dropped": 7,
    }
    r.update(over)
    return r


def test_a_judged_result_becomes_a_row() -> None:
    r = row_of(result(), 3, 11, [20.0, 30.0, 40.0], 150.0)
    assert (r.robots, r.seed, r.outcome, r.contacts, r.wall_s) == (3, 11, "complete", 0, 454.0)
    assert r.exchange_bytes_max == 3000 and r.exchange_bytes_median == 2000.0
    assert r.agreement_s == 4.25 and r.world_ready_s == 21.0 and r.agree_timeout_s == 150.0
    assert r.wave_timeout_s == 600.0 and r.dropped == 7
    assert r.phases == PHASE_WALLS
    assert r.max_abs_r_phi is None  # NaN is no number
    assert (r.load_start, r.load_mean, r.load_end) == (20.0, 30.0, 40.0)
    unsafe = row_of(result(contacts=2), 50, 1, [], 120.0)
    assert unsafe.outcome == "unsafe" and unsafe.load_mean == 0.0
    failed = row_of({"errors": {"demo": "world not ready"}, "contacts": 0}, 100, 1, [9.0], 300)
    assert failed.outcome == "safe_abort" and "world not ready" in failed.detail
    assert failed.phases == {} and failed.agreement_s is None and failed.exchange_bytes_max == 0
    # the real-time factor: the NAOs' own time over the wall time, unknown without it
    assert r.sim_s is None and r.realtime is None
    timed = row_of(result(t_sim_end=113.5), 3, 11, [20.0], 150.0)
    assert timed.sim_s == 113.5 and timed.realtime == pytest.approx(0.25)


def runs() -> list[Run]:
    return [
        row_of(result(wall_total=120.0, phases={"search": {"wall_max": 60.0}}), 10, 1, [18.0],
               120.0),
        row_of(result(), 50, 11, [25.0, 35.0], 150.0),
        row_of(result(contacts=1, silent_wrong=True), 100, 1, [40.0], 300.0),
    ]  # fmt: skip


def test_markdown_tables_hold_every_run_and_phase() -> None:
    text = markdown(runs())
    assert "| 50 | 11 | complete | 0 | 454 | - | 4.2 | 3.0 / 2.0 | no | 25 / 30 / 35 | 7 |" in text
    assert "| 100 | 1 | unsafe | 1 |" in text and "| yes |" in text
    head = next(ln for ln in text.splitlines() if ln.startswith("| N | seed | world start"))
    assert head.split(" | ")[3:-1] == [p for p in PHASES if p in PHASE_WALLS]
    assert "| 10 | 1 | 21 | - | 60 | - |" in text  # phases a run never entered


def test_the_phase_chart_is_drawn(tmp_path: Path) -> None:
    plot_phases(runs(), tmp_path / "chart.png")
    assert (tmp_path / "chart.png").stat().st_size > 5000
    plot_phases(runs()[:1], tmp_path / "one.png")  # a single run, no phases past search
    assert (tmp_path / "one.png").stat().st_size > 3000


def test_report_mode_redraws_from_earlier_files(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rows = [asdict(r) for r in runs()]
    for k, part in enumerate((rows[:2], rows[2:])):
        (tmp_path / f"in{k}.json").write_text(json.dumps({"runs": part}))
    legacy = dict(rows[0])
    del legacy["agree_timeout_s"]  # a file written before the field: the default
    (tmp_path / "old.json").write_text(json.dumps({"runs": [legacy]}))
    out = tmp_path / "out"
    srcs = [str(tmp_path / n) for n in ("in0.json", "in1.json", "old.json")]
    assert main(["--report", *srcs, "--out", str(out), "--figure", str(tmp_path / "f.png")]) == 0
    text = capsys.readouterr().out
    assert "exchange kB/agent" in text and "world start" in text
    assert [r["robots"] for r in json.loads((out / "results.json").read_text())["runs"]] == [
        10, 50, 100, 10
    ]  # fmt: skip
    assert (tmp_path / "f.png").stat().st_size > 5000
    assert "| 100 | 1 | unsafe |" in (out / "table.md").read_text()


def test_load_is_sampled_at_start_during_and_end() -> None:
    values = iter(range(100))
    ticked = threading.Event()

    def read() -> float:
        v = float(next(values))
        if v >= 2:
            ticked.set()
        return v

    with load_samples(period=0.01, read=read) as samples:
        assert ticked.wait(5.0)
    assert samples[0] == 0.0 and len(samples) >= 3
    assert samples == sorted(samples)


def test_arguments_and_the_agreement_timeout() -> None:
    a = parse_args(["--robots", "10", "--robots", "100", "--seed-start", "11"])
    assert a.robots == [10, 100] and a.seed_start == 11 and a.seeds == 1
    assert parse_args([]).robots == [10, 30, 50]
    assert [agree_timeout(a, n) for n in (10, 40, 50, 100)] == [120.0, 120.0, 150.0, 300.0]
    fixed = parse_args(["--agree-timeout", "90", "--wave-timeout", "700"])
    assert agree_timeout(fixed, 100) == 90.0 and wave_timeout(fixed) == 700.0
    assert wave_timeout(parse_args(["--timeout", "3000"])) == 3000.0
    assert parse_args(["--robots", str(MAX_ROBOTS)]).robots == [MAX_ROBOTS]


@pytest.mark.parametrize(
    "argv",
    [
        ["--robots", "1"],
        ["--robots", str(MAX_ROBOTS + 1)],
        ["--seeds", "0"],
        ["--timeout", "0"],
        ["--agree-timeout", "-1"],
        ["--agree-timeout", "0"],
        ["--wave-timeout", "0"],
    ],
)
def test_bad_arguments(argv: list[str]) -> None:
    with pytest.raises(SystemExit):
        parse_args(argv)


def test_bench_scale_is_the_same_tool(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from tools.bench.__main__ import main as bench

    src = tmp_path / "in.json"
    src.write_text(json.dumps({"runs": [asdict(r) for r in runs()]}))
    assert bench(["scale", "--report", str(src), "--out", str(tmp_path / "out")]) == 0
    assert "world start" in capsys.readouterr().out
    assert (tmp_path / "out" / "scale_phases.png").is_file()


def test_a_run_gives_every_agent_the_timeouts(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    import tools.eval_scale as tool

    seen: list[FleetSpec] = []

    def fake_run_fleet(spec: FleetSpec, out: Path, quiet: bool = True) -> dict[str, Any]:
        seen.append(spec)
        return result()

    monkeypatch.setattr(tool, "run_fleet", fake_run_fleet)
    r = run_one(parse_args(["--timeout", "2000"]), 4, 7, tmp_path)
    (spec,) = seen
    assert (spec.robots, spec.seed, spec.timeout, spec.agent.publish_camera) == (4, 7, 2000, False)
    assert (spec.agent.timeout, spec.agent.wave_timeout) == (120.0, 2000.0)
    assert spec.agent_command(2, [])[3:] == ["--id", "2", "--fleet-size", "4",
                                             "--wave-timeout=2000.0"]  # fmt: skip
    assert (r.outcome, r.agree_timeout_s, r.wave_timeout_s) == ("complete", 120.0, 2000.0)
