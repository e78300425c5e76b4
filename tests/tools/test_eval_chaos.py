"""tools.eval_chaos and its libraries (tools.lib.chaos_schedule, chaos_injector, chaos_report):
the seeded schedule (deterministic, every fault kind over a range of seeds), the injector on
a fake fleet, the command line, the
report from a JSON, the figure. No processes: the soak itself needs root and minutes."""

from __future__ import annotations

import json
from collections import Counter
from itertools import pairwise
from pathlib import Path
from typing import Any

import pytest

from tools import eval_chaos
from tools.lib.chaos_injector import Injector
from tools.lib.chaos_report import Run, plot
from tools.lib.chaos_schedule import TAGS, Fault, Limits, Schedule, draw

SEEDS = range(1, 41)


def test_the_schedule_is_a_function_of_the_seed() -> None:
    for seed in SEEDS:
        a, b = draw(seed, 3), draw(seed, 3)
        assert a == b and a.seed == seed
        assert Schedule.from_dict(json.loads(json.dumps(a.to_dict()))) == a
    assert len({draw(s, 3).faults for s in SEEDS}) == len(SEEDS)  # seeds differ
    assert draw(7, 3, horizon_s=60.0) != draw(7, 3)


def test_every_fault_kind_over_a_range_of_seeds() -> None:
    seen: Counter[str] = Counter()
    for seed in SEEDS:
        s = draw(seed, 3)
        assert s.faults or s.reply_delay_s > 0
        seen.update(s.tags())
    assert set(seen) == set(TAGS), seen
    assert all(seen[t] >= 3 for t in TAGS), seen


def test_same_agent_twice_and_two_at_once_are_what_they_say() -> None:
    twice = two = 0
    for seed in SEEDS:
        kills = [f for f in draw(seed, 3).faults if f.kind == "kill-agent"]
        for a, b in pairwise(kills):
            if set(a.robots) & set(b.robots):
                twice += 1
                assert b.t >= a.t + max(a.down_s)  # killed again only after its restart
        for f in kills:
            if len(f.robots) == 2:
                two += 1
                assert f.robots[0] != f.robots[1] and len(f.down_s) == 2
    assert twice >= 3 and two >= 3


@pytest.mark.parametrize("robots", [2, 3, 6])
def test_faults_are_within_their_ranges_and_never_hit_a_robot_that_is_down(robots: int) -> None:
    for seed in SEEDS:
        s = draw(seed, robots, horizon_s=30.0)
        assert s.reply_delay_s == 0 or 0.2 <= s.reply_delay_s <= 2.0
        assert [f.t for f in s.faults] == sorted(f.t for f in s.faults)
        spans: dict[int, list[tuple[float, float]]] = {}
        bursts = []
        for f in s.faults:
            assert f.t >= 0
            if f.kind == "loss":
                assert 0.0 <= f.loss <= 0.5 and 5.0 <= f.duration_s <= 20.0 and f.t <= 30.0
                bursts.append((f.t, f.end()))
                continue
            assert all(1.0 <= d <= 5.0 for d in f.down_s)
            if f.kind == "kill-router":
                assert len(f.down_s) == 1 and 2.0 <= f.t <= 30.0
                continue
            for r, d in zip(f.robots, f.down_s, strict=True):
                assert 1 <= r <= robots
                spans.setdefault(r, []).append((f.t, f.t + d))
        for iv in [*spans.values(), bursts]:
            iv.sort()
            assert all(b0 >= a1 for (_, a1), (b0, _) in pairwise(iv)), iv
        acts = s.actions()
        assert [a.t for a in acts] == sorted(a.t for a in acts)
        kills = sum(a.what == "kill" for a in acts)
        assert kills == sum(a.what == "restart" for a in acts)


def test_limits_shape_the_draw() -> None:
    calm = Limits(max_loss=0.0, max_reply_delay_s=0.0)
    for seed in SEEDS:
        s = draw(seed, 3, limits=calm)
        assert s.reply_delay_s == 0 and all(f.loss == 0 for f in s.faults)
    with pytest.raises(ValueError, match="horizon"):
        draw(1, 3, horizon_s=1.0)


# --------------------------------------------------------------------------- injector


class FakeFleet:
    def __init__(self, ids: list[int]) -> None:
        self.alive = dict.fromkeys(ids, True)
        self.calls: list[tuple[Any, ...]] = []

    def running(self, rid: int) -> bool:
        return self.alive[rid]

    def all_exited(self) -> bool:
        return not any(self.alive.values())

    def kill_agent(self, rid: int) -> None:
        self.alive[rid] = False
        self.calls.append(("kill", rid))

    def start_agent(self, rid: int, append: bool = False) -> None:
        self.alive[rid] = True
        self.calls.append(("start", rid, append))

    def kill_router(self) -> None:
        self.calls.append(("kill-router",))

    def start_router(self) -> None:
        self.calls.append(("start-router",))

    def set_loss(self, loss: float) -> None:
        self.calls.append(("loss", loss))

    def clear_loss(self) -> None:
        self.calls.append(("clear",))


def test_the_injector_walks_the_time_line_and_skips_what_cannot_be() -> None:
    sched = Schedule(
        seed=1,
        robots=3,
        horizon_s=30.0,
        reply_delay_s=0.0,
        faults=(
            Fault(2.0, "kill-agent", (1, 3), (2.0, 3.0)),  # two at once
            Fault(3.0, "loss", loss=0.3, duration_s=5.0),
            Fault(4.0, "kill-router", down_s=(1.0,)),
            Fault(6.0, "kill-agent", (1,), (1.0,)),  # robot 1 again, after its restart
            Fault(9.0, "kill-agent", (2,), (1.0,)),  # robot 2 has exited by then
            Fault(20.0, "kill-router", down_s=(1.0,)),  # the run is over by then
        ),
    )
    fleet = FakeFleet([11, 12, 13])  # the world's ids, in order
    inj = Injector(sched, fleet, [11, 12, 13])
    for t in (0.0, 2.0, 3.5, 4.0, 4.5, 5.0, 6.0, 7.0):
        inj.step(t)
    assert fleet.calls == [
        ("kill", 11), ("kill", 13), ("loss", 0.3), ("start", 11, True),
        ("kill-router",), ("start", 13, True), ("start-router",), ("kill", 11),
        ("start", 11, True),
    ]  # fmt: skip
    assert not inj.pending() and inj.loss_on
    inj.step(8.0)
    assert fleet.calls[-1] == ("clear",) and not inj.loss_on  # the burst's end
    fleet.alive[12] = False  # robot 12 finished
    inj.step(10.0)
    assert fleet.calls[-1] == ("clear",)  # robot 12 neither killed nor restarted
    fleet.alive = dict.fromkeys(fleet.alive, False)  # everyone finished
    inj.step(21.0)
    assert inj.over() and ("kill-router",) not in fleet.calls[-3:]
    inj.finish()
    doc = inj.schedule_doc()
    got = [f["injected_at_s"] for f in doc["faults"]]
    assert got == [2.0, 3.5, 4.0, 6.0, None, None]
    assert doc["faults"][4]["note"] == "robot 12 had exited"
    assert doc["faults"][5]["note"] == "the agents had finished"
    assert doc["injected_tags"] == ["kill", "kill-two", "kill-twice", "router", "loss"]
    assert [e["action"] for e in inj.events][:3] == ["kill", "kill", "loss-on"]


def test_a_burst_still_on_is_cleared_when_the_run_ends() -> None:
    sched = Schedule(1, 2, 30.0, 0.0, (Fault(1.0, "loss", loss=0.5, duration_s=20.0),))
    fleet = FakeFleet([1, 2])
    inj = Injector(sched, fleet, [1, 2])
    inj.step(1.0)
    inj.finish()
    assert fleet.calls == [("loss", 0.5), ("clear",)]


# --------------------------------------------------------------------------- CLI, report


@pytest.mark.parametrize(
    ("argv", "reason"),
    [
        (["--runs", "0"], "--runs"),
        (["--seed-start", "-1"], "--seed-start"),
        (["--robots", "1"], "--robots"),
        (["--robots", "21"], "--robots"),
        (["--horizon", "1"], "--horizon"),
        (["--timeout", "0"], "--timeout"),
        (["--max-loss", "1.5"], "--max-loss"),
        (["--max-reply-delay", "11"], "--max-reply-delay"),
        (["--tcp-rto-max-ms", "5"], "--tcp-rto-max-ms"),
        (["--runs", "x"], "invalid int"),
    ],
)
def test_argument_errors(argv: list[str], reason: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as e:
        eval_chaos.parse_args(argv)
    assert e.value.code == 2 and reason in capsys.readouterr().err


def test_dry_run_prints_and_writes_the_schedules(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["--runs", "2", "--seed-start", "4", "--out", str(tmp_path), "--dry-run"]
    assert eval_chaos.main(argv) == 0
    out = capsys.readouterr().out
    assert "seed 4:" in out and "seed 5:" in out
    doc = json.loads((tmp_path / "seed-004" / "schedule.json").read_text())
    assert Schedule.from_dict(doc) == draw(4, 3, 30.0)


def _run(seed: int, outcome: str, injected: list[float | None]) -> Run:
    sched = draw(seed, 3)
    doc = sched.to_dict()
    for f, t in zip(doc["faults"], injected, strict=False):
        f["injected_at_s"], f["note"] = t, "" if t is not None else "the agents had finished"
    hit = {i for i, t in enumerate(injected) if t is not None}
    return Run(seed, sched.mix(hit), outcome, 0, 60.0, "done", sched.reply_delay_s, 28.0,
               len(hit), 12, doc, [])  # fmt: skip


def test_report_from_a_json_table_and_figure(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    runs = [
        _run(2, "complete", [6.0, 27.0, 29.7, None]),
        _run(6, "safe_abort", [4.0, 26.0, None]),
        _run(10, "complete", [7.2, 19.6, 29.8, 33.4, None]),
    ]
    args = eval_chaos.parse_args(["--out", str(tmp_path), "--json", str(tmp_path / "c.json")])
    eval_chaos.write(args, runs)
    assert (tmp_path / "chaos.png").stat().st_size > 10_000
    doc = json.loads((tmp_path / "c.json").read_text())
    row = doc["runs"][0]
    assert set(row) >= {"seed", "mix", "outcome", "contacts", "wall_s", "detail", "schedule"}
    assert row["schedule"]["faults"][0]["injected_at_s"] == 6.0
    merged = tmp_path / "merged"
    argv = ["--report", str(tmp_path / "c.json"), str(tmp_path / "c.json"), "--out", str(merged)]
    assert eval_chaos.main(argv) == 0
    assert len(json.loads((merged / "results.json").read_text())["runs"]) == 6
    assert (merged / "chaos.png").stat().st_size > 10_000
    out = capsys.readouterr().out
    assert "safe_abort" in out and "kill-two" in out and "all" in out


def test_the_figure_of_a_run_without_an_end(tmp_path: Path) -> None:
    r = _run(3, "safe_abort", [None, None, None])
    r.end_s = None
    plot([r], tmp_path / "one.png")
    assert (tmp_path / "one.png").stat().st_size > 0
