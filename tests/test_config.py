"""The agent's settings (agent/config.py): ``--shape NAME|FILE`` read into a shape (a
built-in, or a formation file with every error naming the file and the field), carried
into the planning parameters and into the agreed parameters' digest."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import pytest

from agent.config import AgentConfig, add_plan_arguments, load_shape
from agent.core.agreed_params import params_digest
from agent.core.formation.shape.spec import BUILTIN, PYRAMID

ROOT = Path(__file__).resolve().parents[1]
TWO = {"name": "pair", "slots": [{"parent": 0, "distance": 1.0, "angle_deg": 90}]}


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
