"""``python -m tools.view``'s planning parameters (tools/view.py ``plan_params``): the
flags given, else a replay's ``result.json``, else the agents' defaults; every bad value
a usage error that names it."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from agent.core.formation.params import PlanParams
from agent.core.formation.shape.spec import BUILTIN
from tools.view import parse_args


def replay(tmp_path: Path, result: object | None, *flags: str) -> PlanParams:
    (tmp_path / "run.mcap").write_bytes(b"")
    if result is not None:
        text = result if isinstance(result, str) else json.dumps(result)
        (tmp_path / "result.json").write_text(text)
    params: PlanParams = parse_args(["--replay", str(tmp_path / "run.mcap"), *flags]).params
    return params


def test_without_flags_or_result_the_agents_defaults() -> None:
    a = parse_args(["--connect", "tcp/127.0.0.1:7447", "--insecure"])
    assert a.params == PlanParams()


def test_the_flags_give_the_fleets_parameters() -> None:
    a = parse_args(["--connect", "tcp/127.0.0.1:7447", "--insecure", "--shape", "wedge",
                    "--d-e", "0.9", "--phi-e-deg", "40", "--orientation", "cp",
                    "--strategy", "banded"])  # fmt: skip
    p = a.params
    assert (p.shape, p.d_e, p.orientation, p.strategy) == (BUILTIN["wedge"], 0.9, "cp", "banded")
    assert p.phi_e == pytest.approx(math.radians(40.0))


def test_a_replay_takes_them_from_the_runs_result_and_a_flag_wins(tmp_path: Path) -> None:
    result = {"shape_spec": "line", "d_e": 1.0, "phi_e_deg": 35.0, "orientation": "north",
              "strategy": "optimal", "seed": 3}  # fmt: skip
    p = replay(tmp_path, result)
    assert (p.shape, p.d_e, p.orientation, p.strategy) == (BUILTIN["line"], 1.0, "north", "optimal")
    assert p.phi_e == pytest.approx(math.radians(35.0))
    p = replay(tmp_path, result, "--shape", "grid", "--d-e", "0.8")
    assert (p.shape, p.d_e, p.orientation) == (BUILTIN["grid"], 0.8, "north")
    assert replay(tmp_path, {"seed": 1}) == PlanParams()  # a result without them


@pytest.mark.parametrize(
    ("result", "flags", "message"),
    [
        ("{not json", [], "result.json: "),
        ([1, 2], [], "not a JSON object"),
        ({"d_e": "far"}, [], "d_e: 'far' is not a number"),
        ({"phi_e_deg": True}, [], "phi_e_deg: True is not a number"),
        ({"shape_spec": 7}, [], "shape: 7 is not a string"),
        ({"orientation": None}, [], "orientation: None is not a string"),
        ({"shape_spec": "hexagon"}, [], "(--shape NAME|FILE gives the fleet's)"),
        ({}, ["--shape", "no/such/file.json"], "no/such/file.json"),
        ({"strategy": "fastest"}, [], "strategy"),
        ({"d_e": -1.0}, [], "planning parameters: "),
    ],
)
def test_a_bad_value_is_a_usage_error_that_names_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], result: object, flags: list[str],
    message: str,
) -> None:  # fmt: skip
    with pytest.raises(SystemExit) as exc:
        replay(tmp_path, result, *flags)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "planning parameters: " in err and message in err, err
