"""tools/harness/fleet.py and hosts.py without processes: what a FleetSpec accepts, the agent
command lines it writes (the agent's defaults never repeated), the scenario it gives the
world, what its result says of it; tools/harness/report.py's matrix of runs."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import pytest

from agent.config import AgentConfig, load_shape
from agent.core.formation.shape.schema import parse_shape
from agent.core.formation.shape.spec import BUILTIN
from agent.core.formation.view.route import Route
from sim import scenarios
from tools import eval_loss
from tools.harness import monitor
from tools.harness.fleet import (
    MAX_ROBOTS,
    Fleet,
    FleetSpec,
    march_room,
    route_length,
    shape_room,
)
from tools.harness.hosts import HostFleet, Hosts
from tools.harness.judge import plan_meta
from tools.harness.report import exit_status, run_matrix
from tools.lib.faults_report import Run

NET = ["--connect", "tcp/127.0.0.1:9"]
ROOT = Path(__file__).resolve().parents[2]
WEDGE = load_shape(str(ROOT / "docs/examples/wedge.json"))  # 9 slots


@pytest.mark.parametrize(
    "over, message",
    [
        ({"robots": 0}, "--robots must be in"),
        ({"robots": MAX_ROBOTS + 1}, "--robots must be in"),
        ({"robots": 1, "isolated": True}, "at least 2 robots"),
        ({"body": "qi"}, "--body"),
        ({"render_workers": 9}, "--render-service"),
        ({"render_workers": 1, "body": "naoqi"}, "--render-service"),
        ({"noise_scale": -1.0}, "--noise-scale"),
        ({"body": "naoqi", "auto_ids": True}, "--auto-ids"),
        ({"timeout": 0.0}, "timeouts"),
        ({"obstacles": -1}, "obstacles"),
        ({"robots": 10, "agent": AgentConfig(robot_id=0, shape=WEDGE)}, "9 slots, too few"),
    ],
)
def test_a_spec_refuses_what_no_run_can_be(over: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        FleetSpec(**over)  # type: ignore[arg-type]


def test_agent_command_lines_repeat_no_default() -> None:
    spec = FleetSpec(robots=4)
    cmd = spec.agent_command(2, NET)
    assert cmd[1:] == ["-m", "agent", "--id", "2", "--fleet-size", "4", *NET]
    odd = replace(
        spec,
        agent=AgentConfig(robot_id=0, timeout=60.0, publish_camera=True),
        agent_args=((3, "--orientation=cp"),),
        agent_log_level="DEBUG",
        auto_ids=True,
    )
    three = odd.agent_command(3, NET, ["--state-dir", "s"])
    assert three[3:] == ["--id", "auto", "--fleet-size", "4", "--timeout=60.0", "--publish-camera",
                         *NET, "--log-level", "DEBUG", "--state-dir", "s", "--orientation=cp"]  # fmt: skip
    assert "--orientation=cp" not in odd.agent_command(2, NET)
    naoqi = replace(spec, body="naoqi").agent_command(1, NET, nao="tcp://h:9559")
    assert naoqi[-4:] == ["--body", "naoqi", "--nao", "tcp://h:9559"]
    assert "--body" not in spec.agent_command(1, NET, nao="tcp://h:9559")  # zenoh: no NAO
    wedge = replace(spec, agent=AgentConfig(robot_id=0, shape=BUILTIN["wedge"]))
    assert wedge.agent_command(1, NET)[3:] == ["--id", "1", "--fleet-size", "4",
                                               "--shape", "wedge", *NET]  # fmt: skip


def test_the_result_says_what_the_run_was() -> None:
    march = AgentConfig(robot_id=0, d_e=0.9, march=Route(distance=2.0))
    meta = FleetSpec(seed=5, agent=march, agent_args=((2, "--sensor-fault=rotate:40"),)).meta()
    assert meta["seed"] == 5 and meta["d_e"] == 0.9 and meta["phi_e_deg"] == 30.0
    assert meta["route"] == {"distance": 2.0} and meta["headings"] == "aligned"
    assert meta["agent_args"] == ["2:--sensor-fault=rotate:40"]  # the judge reads them back
    assert "route" not in FleetSpec().meta() and "agent_args" not in FleetSpec().meta()


def test_a_march_widens_the_room_and_a_world_arg_scenario_wins(tmp_path: Path) -> None:
    to = FleetSpec(robots=4, seed=3, agent=AgentConfig(robot_id=0, march=Route(to=(3.0, 4.0))))
    assert route_length(to.agent) == 7.0 and route_length(AgentConfig(robot_id=0)) == 0.0
    flags = march_room(to, tmp_path)
    base = scenarios.generate(4, 3)
    assert flags[0] == "--scenario" and scenarios.load(flags[1]).room == base.room + 7.0
    assert march_room(replace(to, world_args=("--scenario=x.json",)), tmp_path) == []
    assert march_room(FleetSpec(headings=scenarios.Headings("random")), tmp_path) != []


def test_the_room_holds_the_first_shape_a_wall_spacing_beyond_its_slots(tmp_path: Path) -> None:
    """A line of 10 (seed 201) reaches 3.6 m from its middle: the 3.5 m room of its starts
    grows until every slot stands d_e from a wall; the pyramid of 3 fits its room, and the
    world keeps generating that scenario itself."""
    line = FleetSpec(robots=10, seed=201, agent=AgentConfig(robot_id=0, shape=BUILTIN["line"]))
    base = scenarios.generate(10, 201)
    starts = [(r.x, r.y) for r in base.robots]
    mean = math.hypot(*(sum(c) / len(c) for c in zip(*starts, strict=True)))
    assert base.room == 3.5
    assert shape_room(line, base) == math.ceil(2.0 * (mean + 3.6 + 0.8)) / 2.0
    flags = march_room(line, tmp_path)
    room = scenarios.load(flags[1]).room
    assert room == shape_room(line, base) >= 3.6 + 0.8
    assert scenarios.load(flags[1]).robots == base.robots  # the same starts, more floor
    assert march_room(FleetSpec(robots=3, seed=1), tmp_path) == []
    pyramid = FleetSpec(robots=3, seed=1)
    assert shape_room(pyramid, scenarios.generate(3, 1)) <= scenarios.generate(3, 1).room


def test_a_fleet_judged_before_it_started_has_no_result(tmp_path: Path) -> None:
    fleet = Fleet(FleetSpec(robots=2, seed=1), tmp_path)
    fleet.result["timeout"] = "harness: the world did not start"
    r = fleet.judge()
    assert r["exit_codes"] == {} and r["outcome"] == "safe_abort" and not r["success"]
    assert json.loads((tmp_path / "result.json").read_text())["seed"] == 1
    fleet.close()  # again: nothing


def test_test_hosts_need_credentials_made_for_them() -> None:
    with pytest.raises(ValueError, match="credentials"):
        HostFleet(FleetSpec(), Path("x"), Hosts("t"))
    with pytest.raises(ValueError, match="peer mode"):
        HostFleet(FleetSpec(credentials=Path("c")), Path("x"), Hosts("t", agent_mode="peer"))
    for bad in ({"tcp_rto_max_ms": 999}, {"agent_mode": "router"}, {"loss": 1.5}):
        with pytest.raises(ValueError):
            Hosts("t", **bad)


@pytest.mark.parametrize("shape", ["line", str(ROOT / "docs/examples/wedge.json")])
def test_a_host_fleets_monitor_judges_the_agents_shape(
    shape: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """HostFleet tells its monitor the agents' planning parameters (``monitor_command``),
    and ``tools.eval_loss --monitor`` reads them back into the config it judges with: a
    fleet of the line is judged against the line, not the pyramid."""
    cfg = AgentConfig(robot_id=0, d_e=0.9, phi_e=math.radians(40.0), orientation="cp",
                      strategy="banded", shape=load_shape(shape))  # fmt: skip
    fleet = HostFleet(FleetSpec(robots=3, seed=4, agent=cfg, insecure=True), tmp_path, Hosts("t"))
    argv = fleet.monitor_argv
    assert argv[1:4] == ["-m", "tools.eval_loss", "--monitor"] and argv[-1] == "--insecure"
    seen: dict[str, tuple[object, ...]] = {}

    def judged(*args: object) -> int:
        seen["args"] = args
        return 0

    monkeypatch.setattr(monitor, "monitor", judged)
    assert eval_loss.main(argv[3:]) == 0
    connect, out, agent, *_ = seen["args"]
    assert connect == [fleet.router_ep] and out == tmp_path and isinstance(agent, AgentConfig)
    assert agent.shape == cfg.shape and agent.shape.digest == cfg.shape.digest
    assert (agent.orientation, agent.strategy, agent.d_e) == ("cp", "banded", 0.9)
    assert agent.phi_e == pytest.approx(cfg.phi_e, abs=1e-12)
    assert plan_meta(agent)["shape_spec"] == cfg.shape.source  # what the judge loads again


def test_a_host_fleet_refuses_a_shape_its_monitor_cannot_be_told(tmp_path: Path) -> None:
    made_in_code = parse_shape((ROOT / "docs/examples/wedge.json").read_text())  # no source
    spec = FleetSpec(agent=AgentConfig(robot_id=0, shape=made_in_code), insecure=True)
    with pytest.raises(ValueError, match="cannot be told the shape 'wedge'"):
        HostFleet(spec, tmp_path, Hosts("t"))


def _run(seed: int, outcome: str = "complete") -> Run:
    return Run(seed=seed, fault="kill-agent@move", outcome=outcome, contacts=0, wall_s=1.0,
               detail="")  # fmt: skip


def test_the_matrix_reports_after_every_run_and_rereads_earlier_files(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    seen: list[int] = []
    runs = run_matrix(
        [1, 2, 3],
        lambda s: _run(s, "unsafe" if s == 2 else "complete"),
        report=lambda rs: seen.append(len(rs)),
        progress="t",
        label=lambda s, r: f"{s}:{r.outcome}",
    )
    assert [r.seed for r in runs] == [1, 2, 3] and seen == [1, 2, 3]
    assert "[t]" in capsys.readouterr().err.split("2:unsafe")[0]  # the progress line, labelled
    assert exit_status(runs) == 1
    assert exit_status(runs[:1]) == 0
    path = tmp_path / "runs.json"
    path.write_text(json.dumps({"runs": [r.__dict__ for r in runs]}))
    again = run_matrix([], _run, report=lambda rs: seen.append(-len(rs)), progress="t",
                       label=lambda s, r: "", earlier=[path, path], row=Run)  # fmt: skip
    assert again == runs + runs and seen[-1] == -6


@pytest.mark.parametrize("shape", sorted(BUILTIN))
def test_the_runs_recording_plans_with_the_agents_parameters(shape: str, tmp_path: Path) -> None:
    """The recorder's scene (and so the live view of ``tools.demo --view``) recomputes the
    plan with the agents' parameters: with the pyramid's, a fleet of another shape reports
    a digest the scene never computes, and the page draws no target."""
    from tools.harness.fleet_flags import parse_fleet_spec

    flags = ["--robots", "6", "--shape", shape, "--d-e", "0.9", "--orientation", "north"]
    spec = parse_fleet_spec(flags)
    rec = Fleet(spec, tmp_path).recorder()
    try:
        assert rec.scene.params == spec.agent.plan_params()
        assert rec.scene.params.shape == BUILTIN[shape] and rec.scene.params.d_e == 0.9
    finally:
        rec.close()
