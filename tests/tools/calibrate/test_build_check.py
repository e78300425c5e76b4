"""Build and check on the rendered capture folder: a calibration the agent loads, Table 1 and
the figures, the held-out views passed; captures of caps in another colour (the images'
hue turned) need their own calibration, which build finds and check confirms."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from agent.core.perception.calibration import builtin, load
from agent.core.perception.dbase import DBase, Fit
from tools.calibrate import __main__ as cli
from tools.calibrate.build import build
from tools.calibrate.check import Floors, check
from tools.calibrate.folder import CaptureFolder
from tools.calibrate.orange import learn_orange

HUE_TURN = 90  # OpenCV hue units (180°): orange caps become blue


@pytest.fixture(scope="module")
def built(captures: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("cal")
    build(captures, out)
    return out


def test_the_build_writes_a_calibration_the_agent_loads(built: Path) -> None:
    cal = load(built)
    doc = json.loads((built / "calibration.json").read_text())
    assert doc["digest"] == cal.digest != builtin().digest
    assert doc["dbase"]["fitted"] >= 4 and doc["dbase"]["r2_min"] > 0.99
    kinds = cal.mbase.meta["kinds"]
    assert kinds.count("main") == 4 and kinds.count("head") == 2
    lo, hi = cal.orange.low, cal.orange.high
    assert lo[0] <= 6 <= hi[0] and not cal.orange.wraps  # the rendered caps' hue
    for name in ("orange.png", "dbase.png", "table1.txt"):
        assert (built / "report" / name).stat().st_size > 100
    assert "Table 1" in (built / "report" / "table1.txt").read_text()


def test_the_held_out_views_pass(built: Path, captures: Path) -> None:
    res = check(load(built), captures)
    assert res.positives == 4 and res.views == 6
    assert res.failures(Floors()) == [], res.summary()


def test_check_fails_below_a_floor_and_the_command_says_so(
    built: Path, captures: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cal = load(built)
    wrong = [
        None if f is None else Fit(f.a * 1.3, f.b, f.r2, f.rmse, f.n, f.c) for f in cal.dbase.fits
    ]
    bad = type(cal)(cal.mbase, DBase(wrong, cal.mbase.digest(), cal.dbase.meta), cal.orange)
    assert "within" in " ".join(check(bad, captures).failures(Floors()))
    argv = ["check", "--calibration", str(built), "--captures", str(captures)]
    assert cli.main([*argv, "--min-recall", "1.01", "--report", str(built / "r2")]) == 1
    assert "below the floors: recall" in capsys.readouterr().err
    assert json.loads((built / "r2" / "check.json").read_text())["failed"]
    assert cli.main(argv) == 0


def _turn_hue(src: Path, dst: Path) -> None:
    shutil.copytree(src, dst)
    for p in sorted((dst / "images").glob("*.png")):
        hsv = cv2.cvtColor(cv2.imread(str(p)), cv2.COLOR_BGR2HSV)
        hsv[..., 0] = ((hsv[..., 0].astype(np.int32) + HUE_TURN) % 180).astype(np.uint8)
        cv2.imwrite(str(p), cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR))


def test_caps_of_another_colour_need_and_get_their_own_calibration(
    captures: Path, tmp_path: Path
) -> None:
    blue = tmp_path / "blue"
    _turn_hue(captures, blue)
    assert check(builtin(), blue).recall == 0.0  # the default's orange sees nothing
    built = build(blue, tmp_path / "cal")
    lo, hi = built.calibration.orange.low, built.calibration.orange.high
    assert lo[0] <= 6 + HUE_TURN <= hi[0]
    res = check(load(tmp_path / "cal"), blue)
    assert res.failures(Floors()) == [], res.summary()


def test_no_caps_in_sight_is_an_error(captures: Path) -> None:
    grey = np.full((480, 640, 3), 128, np.uint8)
    with pytest.raises(ValueError, match="no coloured caps"):
        learn_orange([grey, grey], 0.6)
    with pytest.raises(ValueError, match="no M-base views"):
        learn_orange([], 0.6)


def test_a_capture_without_mbase_views_cannot_be_built(captures: Path, tmp_path: Path) -> None:
    cf = CaptureFolder.load(captures)
    part = tmp_path / "part"
    part.mkdir()
    doc = json.loads((captures / "manifest.json").read_text())
    doc["shots"] = [r.to_dict() for r in cf.taken("check")]
    (part / "manifest.json").write_text(json.dumps(doc))
    with pytest.raises(ValueError, match="no M-base views"):
        build(part, tmp_path / "cal")
    assert cli.main(["build", "--captures", str(part), "--out", str(tmp_path / "c")]) == 2
