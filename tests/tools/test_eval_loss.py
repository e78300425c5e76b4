"""tools.eval_loss (and its rows and report, tools.lib.loss_report): the verdict of a run and
the per-loss summary, on hand-made results."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from agent import wire as P
from tools import eval_loss
from tools.harness import report
from tools.harness.hosts import cap_tcp_rto
from tools.harness.procs import free_port, start_router
from tools.harness.procs import stop as stop_proc
from tools.lib.loss_report import RunResult, plot, run_row, summarise
from tools.lib.loss_report import fmt as _fmt
from tools.lib.loss_report import run_reason as _reason


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
    plot(rows, tmp_path / "loss.png")
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
        (["--seed-start", "-1"], "--seed-start"),
        (["--agent-mode", "peer"], "needs --insecure"),
        (["--tcp-rto-max-ms", "999"], "--tcp-rto-max-ms must be 0 or in [1000, 120000]"),
        (["--tcp-rto-max-ms", "120001"], "--tcp-rto-max-ms must be 0 or in [1000, 120000]"),
    ],
)
def test_cli_rejects_bad_arguments(
    argv: list[str], msg: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert eval_loss.main(argv) == 2
    assert msg in capsys.readouterr().err


def test_monitor_is_secure_by_default(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.delenv(P.CREDENTIALS_ENV, raising=False)
    assert eval_loss.main(["--monitor", "--connect", "tls/127.0.0.1:7447"]) == 2
    assert "--credentials" in capsys.readouterr().err


@pytest.mark.system
def test_observer_stops_when_every_agent_is_gone(tmp_path: Path) -> None:
    """The compose observer (``--monitor --until-done N --credentials DIR``) joins a TLS
    router as ``observer``, records a robot's signed status, ends when the agents'
    liveliness tokens are gone even if no final status arrived, and judges the run a
    failure."""
    from agent.net.bus import Bus, BusConfig
    from agent.wire.trust import create_fleet

    fleet = tmp_path / "fleet"
    create_fleet(fleet, [5])
    out = tmp_path / "out"
    ep = f"tls/127.0.0.1:{free_port()}"
    repo = Path(__file__).resolve().parents[2]
    procs = []
    router = start_router(ep, tmp_path, ["--credentials", str(fleet), "--no-multicast-scouting"])
    try:
        mon = subprocess.Popen(
            [
                sys.executable, "-m", "tools.eval_loss", "--monitor", "--until-done", "1",
                "--timeout", "60", "--credentials", str(fleet), "--connect", ep,
                "--out", str(out), "--seed", "4",
            ],
            stdout=subprocess.PIPE, stdin=subprocess.DEVNULL, text=True, cwd=str(repo),
        )  # fmt: skip
        procs.append(mon)
        assert mon.stdout is not None and mon.stdout.readline().strip() == "monitor ready"
        robot = Bus(
            BusConfig(
                connect=(ep,), multicast_scouting=False, mode="client",
                credentials=str(fleet), identity="robot-5",
            )
        )  # fmt: skip
        with robot:
            robot.declare_alive(P.key_alive(5))
            stop = threading.Event()

            def publish() -> None:  # re-published: a fresh session may not know routes yet
                while not stop.wait(0.2):
                    robot.publish(P.key_status(5), P.StatusMsg(sender=5, phase="move"))

            t = threading.Thread(target=publish, daemon=True)
            t.start()
            try:
                # the monitor says when it has seen the status (the readline is bounded by
                # the monitor's own 60 s timeout)
                assert mon.stdout.readline().strip() == "monitor sees agents [5]"
            finally:
                stop.set()
                t.join(timeout=5)
        assert mon.wait(timeout=30) == 1  # not a success: the agent never finished
        result = json.loads((out / "result.json").read_text())
        assert result["exit_codes"] == {"5": None}  # no exit record: it never finished
        assert result["final_phase"] == {"5": "move"}
        assert result["phases_visited"] == {"5": ["move"]}
        assert result["seed"] == 4 and result["success"] is False
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait(timeout=10)
        stop_proc(router)


def _outcome(res: dict[str, object]) -> str:
    return str(run_row(_run(0.3, False, None, [500, 500]), res)["outcome"])


def test_run_rows_take_the_outcome_of_the_one_rule() -> None:
    # complete, safe abort, unsafe: tools.harness.judge.outcome on the monitor's result
    failed = {"exit_codes": {"1": 1, "2": 1}, "final_phase": {"1": "failed", "2": "failed"}}
    assert _outcome(dict(_ok_result(), plan_digests={"1": "a"}, movers=[1])) == "complete"
    assert _outcome(dict(failed, plan_digests={"1": "", "2": ""}, movers=[])) == "safe_abort"
    moved = {**failed, "movers": [1], "contacts": 0}
    shared = dict(moved, plan_digests={"1": "a", "2": "a"}, identical_digests=True)
    assert _outcome(shared) == "safe_abort"  # moved, on the shared plan
    unshared = dict(moved, plan_digests={"1": "a", "2": "b"}, identical_digests=False)
    assert _outcome(unshared) == "unsafe"
    assert _outcome(dict(_ok_result(), contacts=1)) == "unsafe"
    assert _outcome({}) == "no_result"  # the monitor wrote no result: a failure


def test_run_rows_have_the_shared_schema_and_the_outcomes_plot(tmp_path: Path) -> None:
    row = run_row(_run(0.3, True, 2.0, [500, 600]), _ok_result())
    assert row == {
        "seed": 1, "loss": 0.3, "outcome": "complete", "contacts": 0, "wall_s": 10.0,
        "detail": "done, pairs within tolerance",
    }  # fmt: skip
    lost = run_row(_run(0.3, False, None, [500]), {})
    assert lost["outcome"] == "no_result" and lost["detail"] == "x"  # the run's reason
    bad = dict(row, seed=2, outcome="safe_abort", detail="x")
    counts = report.count_outcomes([row, bad], "loss")
    report.plot_outcomes(counts, tmp_path / "outcomes.png", "test")
    assert (tmp_path / "outcomes.png").stat().st_size > 1000


def test_exit_code_zero_is_done_when_the_final_status_went_unheard() -> None:
    from tools.harness.monitor import done_by_exit_code
    from tools.harness.observe import AgentView, Observer

    obs = Observer(0.0)
    phases = {1: ("done", 0), 2: ("hold", 0), 3: ("hold", 1), 4: ("failed", 1), 5: ("march", 0)}
    for i, (phase, code) in phases.items():
        obs.agents[i] = AgentView(phase=phase, exit_code=code)
    obs.agents[6] = AgentView(phase="hold", exit_code=None)  # still running at the timeout
    assert done_by_exit_code(obs, [1, 2, 3, 4, 5, 6, 7]) == [2, 5]
    assert {i: v.phase for i, v in obs.agents.items()} == {
        1: "done", 2: "done", 3: "hold", 4: "failed", 5: "done", 6: "hold",
    }  # fmt: skip


class _Hosts:
    """Records the commands a fabric of ``n`` hosts would run."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.ran: list[tuple[int, list[str]]] = []

    def run(self, index: int, argv: list[str]) -> None:
        self.ran.append((index, argv))


def test_cap_tcp_rto_sets_the_sysctl_on_every_host() -> None:
    hosts = _Hosts(3)
    cap_tcp_rto(hosts, 1000)  # type: ignore[arg-type]
    assert hosts.ran == [
        (i, ["sysctl", "-q", "-w", "net.ipv4.tcp_rto_max_ms=1000"]) for i in (1, 2, 3)
    ]
    for bad in (999, 120001):
        with pytest.raises(ValueError, match="tcp_rto_max_ms must be in"):
            cap_tcp_rto(_Hosts(1), bad)  # type: ignore[arg-type]


def test_exit_records_give_the_processes_exit_codes(tmp_path: Path) -> None:
    """The compose observer's exit codes: the agent containers' exit records."""
    from tools.harness.monitor import read_exits

    (tmp_path / "a.jsonl").write_text('{"robot": 2}\n{"exit": 0}\n')
    (tmp_path / "b.jsonl").write_text('{"robot": 3}\nnot json\n')  # still running
    (tmp_path / "c.jsonl").write_text('{"exit": 1}\n')  # ended before claiming a robot
    stale = tmp_path / "d.jsonl"
    stale.write_text('{"robot": 1}\n{"exit": 0}\n')
    os.utime(stale, (time.time() - 3600, time.time() - 3600))  # an earlier run's
    (tmp_path / "e.txt").write_text(json.dumps({"robot": 5, "exit": 0}))  # not a record
    assert read_exits(tmp_path, time.time() - 60) == ({2: 0, 3: None}, [1])
    assert read_exits(tmp_path / "none", 0.0) == ({}, [])
