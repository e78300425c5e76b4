"""tools/demo.py arguments: fleet parameters, scenario files and the isolated robot."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from sim import scenarios
from tools.demo import march_room, parse_args


def test_fleet_parameters_default_and_pass_through() -> None:
    a = parse_args([])
    assert (a.orientation, a.strategy, a.scenario, a.isolated) == ("pca", "default", None, False)
    a = parse_args(["--orientation", "cp", "--strategy", "capt"])
    assert (a.orientation, a.strategy) == ("cp", "capt")


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
