"""agent/config.py: the agent's settings written back as its command line
(:meth:`AgentConfig.to_argv`), the inverse of ``python -m agent``'s parser; ``--shape
NAME|FILE`` read into a shape (a built-in, or a formation file with every error naming the
file and the field), carried into the planning parameters and into the agreed parameters'
digest."""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import replace
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.__main__ import agent_config, parse_args
from agent.config import AgentConfig, add_plan_arguments, load_shape
from agent.core.agreed_params import params_digest
from agent.core.formation.params import D_E, ORIENTATIONS, PHI_E_DEG, PLAN_STRATEGIES
from agent.core.formation.shape.schema import parse_shape
from agent.core.formation.shape.spec import BUILTIN, PYRAMID
from agent.core.formation.view.route import Route
from agent.core.perception.sensor_fault import SensorFault
from agent.wire import MAX_ROBOT_ID

ROOT = Path(__file__).resolve().parents[1]
TWO = {"name": "pair", "slots": [{"parent": 0, "distance": 1.0, "angle_deg": 90}]}


def parsed(cfg: AgentConfig, claim_id: bool = False) -> AgentConfig:
    """What an agent started with ``cfg.to_argv()`` runs with."""
    return agent_config(parse_args(cfg.to_argv(claim_id=claim_id)), cfg.robot_id)


def positive(hi: float) -> st.SearchStrategy[float]:
    return st.floats(min_value=1e-3, max_value=hi, allow_nan=False, allow_infinity=False)


routes = st.one_of(
    st.none(),
    st.builds(lambda d: Route(distance=d), positive(50.0)),
    st.builds(
        lambda x, y: Route(to=(x, y)),
        st.floats(-1000.0, 1000.0, allow_nan=False),
        st.floats(-1000.0, 1000.0, allow_nan=False),
    ),
)
faults = st.one_of(
    st.none(),
    st.builds(SensorFault, st.just("rotate"), st.floats(-360.0, 360.0, allow_nan=False)),
    st.builds(SensorFault, st.just("scale"), st.floats(0.1, 10.0, allow_nan=False)),
    st.builds(SensorFault, st.just("shift"), st.floats(-5.0, 5.0, allow_nan=False)),
)
#: every built-in, and a formation file's shape (written back as its path)
shapes = st.sampled_from([*BUILTIN.values(), load_shape(str(ROOT / "docs/examples/wedge.json"))])
configs = st.builds(
    AgentConfig,
    robot_id=st.integers(0, MAX_ROBOT_ID),
    d_e=st.one_of(st.just(D_E), positive(10.0)),
    # phi_e as --phi-e-deg gives it: the radians of some degrees in (0, 90)
    phi_e=st.one_of(
        st.just(math.radians(PHI_E_DEG)),
        st.floats(0.01, 89.99, allow_nan=False).map(math.radians),
    ),
    orientation=st.sampled_from(ORIENTATIONS),
    strategy=st.sampled_from(PLAN_STRATEGIES),
    shape=shapes,
    timeout=st.one_of(st.just(AgentConfig.timeout), positive(1e5)),
    wave_timeout=st.one_of(st.just(AgentConfig.wave_timeout), positive(1e5)),
    member_grace=st.one_of(st.just(AgentConfig.member_grace), positive(1e3)),
    correct=st.booleans(),
    march=routes,
    research_rounds=st.integers(0, 10),
    explore_step=st.floats(0.2, 5.0, allow_nan=False),
    sensor_fault=faults,
    publish_camera=st.booleans(),
).flatmap(  # a fleet size the shape holds (a formation file has so many slots)
    lambda c: st.one_of(st.none(), st.integers(1, c.shape.capacity or 200)).map(
        lambda n: replace(c, fleet_size=n)
    )
)


@settings(deadline=None)  # argparse on a loaded machine: no timing to hold
@given(configs)
def test_the_command_line_gives_the_config_back(cfg: AgentConfig) -> None:
    assert parsed(cfg) == cfg


def test_only_what_differs_from_the_defaults_is_written() -> None:
    assert AgentConfig(robot_id=3).to_argv() == ["--id", "3"]
    assert AgentConfig(robot_id=3, fleet_size=4).to_argv(claim_id=True) == [
        "--id", "auto", "--fleet-size", "4",
    ]  # fmt: skip
    cfg = AgentConfig(robot_id=1, d_e=0.9, phi_e=math.radians(40.0), timeout=60.0,
                      correct=False, march=Route(to=(-1.5, 2.0)))  # fmt: skip
    assert cfg.to_argv() == ["--id", "1", "--phi-e-deg", "40.0", "--d-e=0.9", "--timeout=60.0",
                             "--no-correct", "--march-to=-1.5,2.0"]  # fmt: skip
    assert parsed(cfg) == cfg and cfg.phi_e_deg == 40.0
    assert AgentConfig(robot_id=1).phi_e_deg == PHI_E_DEG


def test_a_setting_no_flag_carries_is_refused() -> None:
    with pytest.raises(ValueError, match="settle"):
        AgentConfig(robot_id=1, settle=1.0).to_argv()


def test_the_shape_is_written_as_its_name_or_file_and_the_pyramid_not_at_all(
    tmp_path: Path,
) -> None:
    assert "--shape" not in AgentConfig(robot_id=1, shape=PYRAMID).to_argv()
    assert AgentConfig(robot_id=1, shape=BUILTIN["line"]).to_argv() == [
        "--id", "1", "--shape", "line",
    ]  # fmt: skip
    f = tmp_path / "pair.json"
    f.write_text(json.dumps(TWO))
    pair = AgentConfig(robot_id=1, fleet_size=2, shape=load_shape(str(f)))
    assert pair.to_argv()[-2:] == ["--shape", str(f.resolve())]  # whatever the agent's cwd
    assert parsed(pair) == pair
    # a shape built in code, loaded from no file: no flag can give it to an agent
    with pytest.raises(ValueError, match="no python -m agent flag sets the shape 'pair'"):
        AgentConfig(robot_id=1, shape=parse_shape(json.dumps(TWO))).to_argv()


def test_built_ins_by_name() -> None:
    for name, shape in BUILTIN.items():
        assert load_shape(name) is shape and shape.source == name


def test_a_formation_file(tmp_path: Path) -> None:
    f = tmp_path / "pair.json"
    f.write_text(json.dumps(TWO))
    shape = load_shape(str(f))
    assert shape.name == "pair" and shape.capacity == 2
    assert shape.source == str(f.resolve())  # what the demo gives every agent
    assert load_shape(str(ROOT / "docs/examples/wedge.json")).name == "wedge"


def test_a_yaml_formation_file_is_the_same_shape(tmp_path: Path) -> None:
    """The YAML example defines the JSON example's slots: the same digest."""
    from_yaml = load_shape(str(ROOT / "docs/examples/wedge.yaml"))
    assert from_yaml.digest == load_shape(str(ROOT / "docs/examples/wedge.json")).digest
    f = tmp_path / "pair.yml"
    f.write_text("name: pair\nslots:\n  - {parent: 0, distance: 0.8, angle_deg: 180}\n")
    assert load_shape(str(f)).capacity == 2


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("name: [unclosed\n", r"not YAML \(.* at line 2, column 1\)"),
        ("- 1\n- 2\n", r"expected an object"),
        ("name: x\nslots:\n  - {parent: 3, distance: 0.8, angle_deg: 0}\n",
         r"slots\[0\]\.parent: 3 is not an earlier slot"),
        ("name: x\nslots:\n  - {parent: 0, distance: far, angle_deg: 0}\n",
         r"slots\[0\]\.distance: expected a number"),
        ("name: x\ncolour: red\nslots: []\n", r"unknown field 'colour'"),
    ],
)  # fmt: skip
def test_yaml_file_errors_name_the_field(tmp_path: Path, text: str, match: str) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text(text)
    with pytest.raises(ValueError, match=rf"^shape file {bad}: .*{match}"):
        load_shape(str(bad))


def test_file_errors_name_the_file_and_the_field(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"shape 'nope': neither a built-in \(pyramid, line"):
        load_shape("nope")
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({**TWO, "slots": [{"parent": 0, "distance": -1, "angle_deg": 0}]}))
    with pytest.raises(ValueError, match=rf"^shape file {bad}: slots\[0\]\.distance: expected > 0"):
        load_shape(str(bad))
    bad.write_text("{")
    with pytest.raises(ValueError, match=r"not JSON"):
        load_shape(str(bad))
    bad.write_bytes(b"\xff\xfe")
    with pytest.raises(ValueError, match=rf"^shape file {bad}: .*codec"):
        load_shape(str(bad))
    tight = {**TWO, "slots": [*TWO["slots"], {"parent": 1, "distance": 0.2, "angle_deg": 180}]}
    bad.write_text(json.dumps(tight))
    with pytest.raises(ValueError, match=r"slots 1 and 2 are 0.200 m apart"):
        load_shape(str(bad))


def test_the_shape_argument(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    p = argparse.ArgumentParser()
    add_plan_arguments(p)
    assert p.parse_args([]).shape is PYRAMID
    assert p.parse_args(["--shape", "grid"]).shape is BUILTIN["grid"]
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"name": "x", "slots": [{**TWO["slots"][0], "parent": 3}]}))
    with pytest.raises(SystemExit) as exc:
        p.parse_args(["--shape", str(bad)])
    assert exc.value.code == 2
    assert "slots[0].parent: 3 is not an earlier slot (0..0)" in capsys.readouterr().err


def test_a_fleet_larger_than_its_formation_file_is_refused_at_start(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    f = tmp_path / "pair.json"
    f.write_text(json.dumps(TWO))
    pair = load_shape(str(f))
    why = rf"shape 'pair' \(file {f.resolve()}\) has 2 slots, too few for 3 robots"
    with pytest.raises(ValueError, match=why):
        AgentConfig(robot_id=1, fleet_size=3, shape=pair)
    assert AgentConfig(robot_id=1, fleet_size=2, shape=pair).fleet_size == 2  # it fits
    assert AgentConfig(robot_id=1, shape=pair).fleet_size is None  # learnt at agreement
    with pytest.raises(SystemExit) as exc:
        parse_args(["--id", "1", "--fleet-size", "3", "--shape", str(f)])
    assert exc.value.code == 2
    assert "--shape: shape 'pair' (file " in capsys.readouterr().err
    assert parse_args(["--id", "1", "--fleet-size", "2", "--shape", str(f)]).shape == pair
    assert parse_args(["--id", "1", "--shape", str(f)]).fleet_size is None


def test_the_shape_is_planned_with_and_agreed() -> None:
    line = AgentConfig(robot_id=1, shape=BUILTIN["line"])
    assert line.plan_params().shape is BUILTIN["line"]
    assert line.agreed_params()["shape"] == BUILTIN["line"].digest
    digests = {
        params_digest(AgentConfig(robot_id=1, shape=s).agreed_params()) for s in BUILTIN.values()
    }
    assert len(digests) == len(BUILTIN)  # agents told different shapes never agree
    assert AgentConfig(robot_id=2).plan_params().shape is PYRAMID
    assert AgentConfig(robot_id=2, phi_e=math.radians(40)).agreed_params()["shape"] == (
        PYRAMID.digest
    )
