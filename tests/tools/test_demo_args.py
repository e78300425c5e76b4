"""tools/demo.py arguments (tools.harness.fleet_flags): fleet parameters, scenario files and
the isolated robot, read into the run's FleetSpec."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from sim import scenarios
from tools.demo import parse_args
from tools.harness.fleet import march_room


def test_fleet_parameters_default_and_pass_through() -> None:
    a = parse_args([])
    assert (a.orientation, a.strategy, a.scenario, a.isolated) == ("pca", "default", None, False)
    assert a.spec.agent.to_argv() == ["--id", "0", "--publish-camera"]  # the agent's defaults
    a = parse_args(["--orientation", "cp", "--strategy", "capt", "--d-e", "0.9",
                    "--phi-e-deg", "25", "--agree-timeout", "60", "--march-to", "1,-2"])  # fmt: skip
    cfg = a.spec.agent
    assert (cfg.orientation, cfg.strategy, cfg.d_e, cfg.phi_e_deg) == ("cp", "capt", 0.9, 25.0)
    assert cfg.timeout == 60.0 and cfg.march is not None and cfg.march.to == (1.0, -2.0)
    assert a.spec.meta()["route"] == {"to": [1.0, -2.0]} and a.spec.meta()["phi_e_deg"] == 25.0


def test_agent_arg_goes_to_that_agent_only(tmp_path: Path) -> None:
    from tools.harness.procs import start_agent

    a = parse_args(["--agent-arg", "3:--orientation=cp", "--agent-arg", "3:--d-e=0.9"])
    assert a.spec.agent_args == ((3, "--orientation=cp"), (3, "--d-e=0.9"))
    cmds: dict[int, list[str]] = {}
    for rid in (2, 3):
        cmd = a.spec.agent_command(rid, ["--insecure", "--help"])
        proc = start_agent(cmd, tmp_path / f"agent-{rid}.log")
        assert proc.popen.wait(60) == 0  # the agent took every flag (--help: and stopped)
        proc.log.close()
        cmds[rid] = [str(c) for c in proc.popen.args]  # type: ignore[union-attr]
    assert cmds[3][-2:] == ["--orientation=cp", "--d-e=0.9"]
    assert cmds[3][3:7] == ["--id", "3", "--fleet-size", "3"]
    assert not any(c.startswith("--orientation=") for c in cmds[2])
    for bad in ("x:--a", "3--a", "3:a"):
        with pytest.raises(SystemExit):
            parse_args(["--agent-arg", bad])


def test_scenario_file_gives_the_robots_and_the_seed(tmp_path: Path) -> None:
    sc = scenarios.generate(3, 4)
    sc = replace(sc, robots=tuple(replace(r, id=i) for r, i in zip(sc.robots, (2, 5, 7))))
    path = tmp_path / "sc.json"
    scenarios.dump(sc, path)
    a = parse_args(["--scenario", str(path), "--robots", "9"])
    assert (a.robots, a.seed, a.scenario_ids) == (3, 4, [2, 5, 7])
    # the world gets the file (copied to the run's folder)
    flags = march_room(a.spec, tmp_path)
    assert flags[0] == "--scenario" and scenarios.load(flags[1]) == sc


def test_isolated_scenario_is_written_for_the_world(tmp_path: Path) -> None:
    a = parse_args(["--robots", "4", "--isolated", "--seed", "3"])
    flags = march_room(a.spec, tmp_path)
    assert scenarios.load(flags[1]) == scenarios.generate(4, 3, isolated=True)
    assert march_room(parse_args([]).spec, tmp_path) == []  # the world generates it


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--scenario", "{missing}"], "--scenario"),
        (["--scenario", "{bad}"], "not JSON"),
        (["--scenario", "{good}", "--batch", "3"], "no --batch"),
        (["--scenario", "{good}", "--isolated"], "not allowed with"),
        (["--robots", "1", "--isolated"], "at least 2 robots"),
        (["--orientation", "south"], "invalid choice"),
        (["--d-e", "-1"], "d_e must be > 0"),
        (["--march", "0"], "march distance"),
        (["--march-to", "1"], "X,Y"),
    ],
)
def test_usage_errors(
    argv: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "bad.json").write_text("{")
    scenarios.dump(scenarios.generate(2, 1), tmp_path / "good.json")
    files = {k: str(tmp_path / f"{k}.json") for k in ("missing", "bad", "good")}
    with pytest.raises(SystemExit) as exc:
        parse_args([arg.format(**files) for arg in argv])
    assert exc.value.code == 2 and message in capsys.readouterr().err


def test_a_fleet_larger_than_its_formation_file_is_a_usage_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import json

    f = tmp_path / "pair.json"
    slot = {"parent": 0, "distance": 1, "angle_deg": 90}
    f.write_text(json.dumps({"name": "pair", "slots": [slot]}))
    three = tmp_path / "three.json"
    scenarios.dump(scenarios.generate(3, 1), three)
    for argv in (["--robots", "3"], ["--scenario", str(three)]):  # the robots, or the file's
        with pytest.raises(SystemExit) as exc:
            parse_args([*argv, "--shape", str(f)])
        err = capsys.readouterr().err
        assert exc.value.code == 2 and "has 2 slots, too few for 3 robots" in err
    assert parse_args(["--robots", "2", "--shape", str(f)]).spec.robots == 2


def test_the_demo_turns_the_camera_feed_on_and_other_tools_leave_it_off() -> None:
    from agent.config import AgentConfig
    from tools.harness.fleet import FleetSpec
    from tools.harness.fleet_flags import parse_fleet_spec

    def cmd(spec: FleetSpec) -> list[str]:
        return spec.agent_command(1, ["--connect", "tcp/127.0.0.1:9"])

    assert parse_args([]).publish_camera is True
    assert "--publish-camera" in cmd(parse_args([]).spec)
    assert "--publish-camera" not in cmd(parse_args(["--no-publish-camera"]).spec)
    # the eval tools' own specs: the agent's default, no camera frames
    assert "--publish-camera" not in cmd(FleetSpec(agent=AgentConfig(robot_id=0)))
    # tools.eval_headings asks the demo for none unless its --demo-arg asks
    assert parse_fleet_spec(["--no-publish-camera", "--publish-camera"]).agent.publish_camera


def test_render_service_workers_and_what_they_served(tmp_path: Path) -> None:
    from tools.harness.render import render_command, served, served_by

    assert parse_args([]).render_service == 0
    assert parse_args(["--render-service", "2"]).render_service == 2
    for bad in (["--render-service", "9"], ["--render-service", "1", "--body", "naoqi"]):
        with pytest.raises(SystemExit):
            parse_args(bad)
    cmd = render_command(["--connect", "tls/h:1"], (2, 3))
    assert cmd[1:] == ["-m", "sim.server.render_worker", "--connect", "tls/h:1", "--shard", "2/3"]
    (tmp_path / "render-1.log").write_text(
        "render ready robots=1,3 shard=1/2 seed=1\n"
        "[render t=   65.00] served camera=207 (260 ms); errors=0 rejected=0\n"
    )
    (tmp_path / "render-2.log").write_text("render ready robots=2 shard=2/2 seed=1\n")
    assert served(tmp_path / "render-1.log") == 207
    assert served_by(tmp_path, 3) == {"render-1": 207, "render-2": None, "render-3": None}


def test_the_shape_goes_to_every_agent_and_into_the_result(tmp_path: Path) -> None:
    import json

    from agent.core.formation.shape.spec import BUILTIN, PYRAMID

    net = ["--connect", "tcp/127.0.0.1:9"]
    a = parse_args([])
    assert a.shape is PYRAMID and a.spec.agent.shape is PYRAMID
    assert "--shape" not in a.spec.agent_command(1, net)  # the default: the agents' own
    assert a.spec.meta()["shape_spec"] == "pyramid"
    line = parse_args(["--shape", "line"]).spec
    argv = line.agent_command(1, net)
    assert argv[argv.index("--shape") + 1] == "line" and line.agent.shape is BUILTIN["line"]
    assert line.meta()["shape_spec"] == "line"  # what the judge loads again
    assert line.meta()["shape_digest"] == BUILTIN["line"].digest
    f = tmp_path / "trio.json"
    slot = {"parent": 0, "distance": 1, "angle_deg": 90}
    f.write_text(json.dumps({"name": "p", "slots": [slot, {**slot, "angle_deg": -90}]}))
    spec = parse_args(["--shape", str(f)]).spec
    assert spec.agent.shape.name == "p"
    argv = spec.agent_command(2, net)
    assert argv[argv.index("--shape") + 1] == str(f.resolve())  # whatever the agents' cwd
    assert spec.meta()["shape_spec"] == str(f.resolve())


def test_the_worlds_look_and_free_looks_go_to_the_world(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from sim.camera.look import Look
    from tools.harness.fleet import Fleet

    a = parse_args([])
    assert a.spec.look.is_default() and not a.spec.free_looks
    assert "--look" not in Fleet(a.spec, tmp_path)._world_flags()
    a = parse_args(["--look", "teal-caps,noise:2", "--free-looks"])
    assert a.spec.look == Look.parse("teal-caps,noise:2")
    flags = Fleet(a.spec, tmp_path)._world_flags()
    assert flags[-3:] == ["--look", str(a.spec.look), "--free-looks"]
    assert a.spec.meta()["look"] == str(a.spec.look) and a.spec.meta()["free_looks"]
    with pytest.raises(SystemExit):
        parse_args(["--look", "hue:999"])
    assert "outside [-180, 180]" in capsys.readouterr().err


def test_the_calibration_goes_to_every_agent_and_a_bad_folder_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from agent.core.perception.calibration import builtin

    net = ["--connect", "tcp/127.0.0.1:9"]
    assert "--calibration" not in parse_args([]).spec.agent_command(1, net)
    folder = tmp_path / "cal"
    builtin().save(folder, {"source": "a test: the built-in calibration written out"})
    spec = parse_args(["--calibration", str(folder)]).spec
    for rid in (1, 2):
        argv = spec.agent_command(rid, net)
        assert argv[argv.index("--calibration") + 1] == str(folder.resolve())
    assert spec.meta()["calibration"] == str(folder.resolve())
    (folder / "orange.json").write_text("{}")
    with pytest.raises(SystemExit) as stop:
        parse_args(["--calibration", str(folder)])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert f"--calibration {folder}" in err and "orange.json" in err


def test_the_wall_limit_follows_the_fleet_unless_given() -> None:
    """The agents' wall limit is the harness's last resort: 600 s up to 30 robots, 20 s a
    robot beyond (100 NAOs on two cores agreed after 456 s and were cut at 600 s), and
    ``--timeout`` wins."""
    from tools.harness.fleet import wall_limit

    assert parse_args([]).spec.wall == 600.0
    assert parse_args(["--robots", "100"]).spec.wall == 2000.0 == wall_limit(100)
    assert parse_args(["--robots", "100", "--timeout", "90"]).spec.wall == 90.0
    with pytest.raises(SystemExit):
        parse_args(["--timeout", "0"])
