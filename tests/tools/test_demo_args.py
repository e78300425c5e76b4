"""tools/demo.py arguments: fleet parameters, scenario files and the isolated robot."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from sim import scenarios
from tools.demo import parse_args
from tools.harness.run import march_room


def test_fleet_parameters_default_and_pass_through() -> None:
    a = parse_args([])
    assert (a.orientation, a.strategy, a.scenario, a.isolated) == ("pca", "default", None, False)
    a = parse_args(["--orientation", "cp", "--strategy", "capt"])
    assert (a.orientation, a.strategy) == ("cp", "capt")


def test_agent_arg_goes_to_that_agent_only(tmp_path: Path) -> None:
    from tools.harness.procs import start_agent

    a = parse_args(["--agent-arg", "3:--orientation=cp", "--agent-arg", "3:--d-e=0.9"])
    assert a.agent_arg == [(3, "--orientation=cp"), (3, "--d-e=0.9")]
    cmds: dict[int, list[str]] = {}
    for rid in (2, 3):
        proc = start_agent(rid, 3, "tcp/127.0.0.1:9", tmp_path, a, ["--insecure", "--help"])
        proc.popen.wait(60)
        proc.log.close()
        cmds[rid] = [str(c) for c in proc.popen.args]  # type: ignore[union-attr]
    assert cmds[3][-2:] == ["--orientation=cp", "--d-e=0.9"]
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
    flags = march_room(a, a.robots, a.seed, tmp_path)
    assert flags[0] == "--scenario" and scenarios.load(flags[1]) == sc


def test_isolated_scenario_is_written_for_the_world(tmp_path: Path) -> None:
    a = parse_args(["--robots", "4", "--isolated"])
    flags = march_room(a, 4, 3, tmp_path)
    assert scenarios.load(flags[1]) == scenarios.generate(4, 3, isolated=True)
    assert march_room(parse_args([]), 4, 3, tmp_path) == []  # the world generates it


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--scenario", "{missing}"], "--scenario"),
        (["--scenario", "{bad}"], "not JSON"),
        (["--scenario", "{good}", "--batch", "3"], "no --batch"),
        (["--scenario", "{good}", "--isolated"], "not allowed with"),
        (["--robots", "1", "--isolated"], "at least 2 robots"),
        (["--orientation", "north"], "invalid choice"),
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


def test_the_demo_turns_the_camera_feed_on_and_other_tools_leave_it_off() -> None:
    import argparse

    from tools.harness.procs import agent_command

    def cmd(a: argparse.Namespace) -> list[str]:
        return agent_command(1, 3, "tcp/127.0.0.1:9", a)

    assert parse_args([]).publish_camera is True
    assert "--publish-camera" in cmd(parse_args([]))
    assert "--publish-camera" not in cmd(parse_args(["--no-publish-camera"]))
    # the eval tools' own namespaces know no such setting: their agents publish none
    bare = argparse.Namespace(d_e=0.8, phi_e_deg=30.0, agree_timeout=60.0, agent_log_level="INFO")
    assert "--publish-camera" not in cmd(bare)
    # tools.eval_headings asks the demo for none unless its --demo-arg asks
    assert parse_args(["--no-publish-camera", "--publish-camera"]).publish_camera is True


def test_render_service_workers_and_what_they_served(tmp_path: Path) -> None:
    from tools.harness.render import render_command, served, served_by

    assert parse_args([]).render_service == 0
    assert parse_args(["--render-service", "2"]).render_service == 2
    for bad in (["--render-service", "9"], ["--render-service", "1", "--body", "naoqi"]):
        with pytest.raises(SystemExit):
            parse_args(bad)
    cmd = render_command(["--connect", "tls/h:1"], (2, 3))
    assert cmd[1:] == ["-m", "sim.render_worker", "--connect", "tls/h:1", "--shard", "2/3"]
    (tmp_path / "render-1.log").write_text(
        "render ready robots=1,3 shard=1/2 seed=1\n"
        "[render t=   65.00] served camera=207 (260 ms); errors=0 rejected=0\n"
    )
    (tmp_path / "render-2.log").write_text("render ready robots=2 shard=2/2 seed=1\n")
    assert served(tmp_path / "render-1.log") == 207
    assert served_by(tmp_path, 3) == {"render-1": 207, "render-2": None, "render-3": None}


def test_the_shape_goes_to_every_agent_and_into_the_result(tmp_path: Path) -> None:
    import argparse
    import json

    from agent.core.formation.shape.spec import BUILTIN, PYRAMID
    from tools.harness.procs import agent_command

    def cmd(a: argparse.Namespace) -> list[str]:
        return agent_command(1, 3, "tcp/127.0.0.1:9", a)

    assert parse_args([]).shape is PYRAMID
    assert "--shape" not in cmd(parse_args([]))  # the default: the agents' own
    argv = cmd(parse_args(["--shape", "line"]))
    assert argv[argv.index("--shape") + 1] == "line"
    f = tmp_path / "pair.json"
    f.write_text(json.dumps({"name": "p", "slots": [{"parent": 0, "distance": 1, "angle_deg": 0}]}))
    a = parse_args(["--shape", str(f)])
    assert a.shape.name == "p"
    argv = cmd(a)
    assert argv[argv.index("--shape") + 1] == str(f.resolve())  # whatever the agents' cwd
    # a name or path on another tool's namespace passes as it is
    bare = argparse.Namespace(d_e=0.8, phi_e_deg=30.0, agree_timeout=60.0, agent_log_level="INFO")
    assert "--shape" not in cmd(bare)
    bare.shape = "grid"
    assert cmd(bare)[cmd(bare).index("--shape") + 1] == "grid"
    assert BUILTIN["grid"].source == "grid"
