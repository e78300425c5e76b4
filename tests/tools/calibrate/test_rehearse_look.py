"""A rehearsal's world in a look (tools/calibrate/rehearse.py, ``rehearse --look SPEC``)."""

from __future__ import annotations

import pytest

from sim.camera.look import Look
from tools.calibrate.__main__ import parser
from tools.calibrate.rehearse import make_world


def test_the_rehearsal_world_takes_the_look_named() -> None:
    with make_world("teal-caps,noise:2", seed=1, noise=False) as w:
        assert w.look == Look.parse("teal-caps,noise:2")
    with pytest.raises(ValueError, match="neither KEY:VALUE nor a preset"):
        make_world("sunny")


def test_the_command_line_checks_the_look(capsys: pytest.CaptureFixture[str]) -> None:
    args = parser().parse_args(["rehearse", "--look", "dim-warm", "--out", "x"])
    assert args.look == str(Look.parse("dim-warm"))
    with pytest.raises(SystemExit):
        parser().parse_args(["rehearse", "--look", "light:9", "--out", "x"])
    assert "outside [0.05, 4]" in capsys.readouterr().err
