"""A lab's calibration end to end: ``python -m tools.calibrate rehearse`` captures, builds
and checks over the real qi protocol against virtual NAOs (the simulated world and its qi
gateway) in a look unlike the built-in calibration's (``teal-caps``), on a coarse grid;
then three NAOs over qi in that look form the pyramid with the calibration it built, and
without it stop, saying that nobody saw anybody (no walk, no contact)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from agent.core.perception.calibration import builtin, load
from tests.system.world import run_demo
from tools.calibrate.folder import CaptureFolder
from tools.calibrate.plan import coarse

pytestmark = [pytest.mark.system, pytest.mark.slow]
ROOT = Path(__file__).resolve().parents[2]
LOOK = "teal-caps"


@pytest.fixture(scope="module")
def rehearsal(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """The rehearsal's folder and its standard output."""
    out = tmp_path_factory.mktemp("calibrate") / "rehearsal"
    res = subprocess.run(
        [sys.executable, "-m", "tools.calibrate", "rehearse", "--look", LOOK,
         "--grid", "coarse", "--out", str(out)],
        cwd=ROOT, capture_output=True, text=True, timeout=900,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr[-3000:]
    return out, res.stdout


def test_rehearse_leaves_a_checked_calibration(rehearsal: tuple[Path, str]) -> None:
    out, stdout = rehearsal
    cal = load(out / "calibration")
    assert cal.digest != builtin().digest
    assert f"calibration {cal.digest}" in stdout
    report = json.loads((out / "calibration" / "report" / "check.json").read_text())
    assert report["failed"] == [] and report["positives"] >= 10
    caps = CaptureFolder.load(out / "captures")
    assert len(caps.records) == len(coarse().shots())
    assert caps.header["robots"]["observer"]["url"].startswith("tcp://127.0.0.1:")
    assert caps.header["look"] == "hue:167.0,sat:0.8"
    assert (out / "captures" / "contact_sheet.png").is_file()
    lo, hi = cal.orange.low, cal.orange.high  # the teal caps' hue (OpenCV 90), not orange
    assert lo[0] <= 90 <= hi[0]


def test_the_fleet_forms_with_the_calibration_and_stops_without_it(
    rehearsal: tuple[Path, str], tmp_path: Path
) -> None:
    out, _ = rehearsal
    flags = ["--robots", "3", "--seed", "1", "--body", "naoqi", "--look", LOOK, "--insecure"]
    (tmp_path / "with").mkdir()
    (tmp_path / "without").mkdir()
    res, result = run_demo(tmp_path / "with", *flags, "--calibration", str(out / "calibration"))
    assert res.returncode == 0 and result["outcome"] == "complete", res.stdout[-3000:]
    assert result["contacts"] == 0
    res, result = run_demo(tmp_path / "without", *flags)
    assert res.returncode != 0 and result["outcome"] == "safe_abort", res.stdout[-3000:]
    assert result["contacts"] == 0 and max(result["moved_m"].values()) < 0.05
    assert all("no robot saw any other" in e for e in result["errors"].values())


def test_a_look_the_world_cannot_render_is_refused(tmp_path: Path) -> None:
    """A malformed look is refused before anything starts (argparse's exit 2)."""
    from tools.calibrate import __main__ as cli

    with pytest.raises(SystemExit) as stop:
        cli.main(["rehearse", "--look", "hue:abc", "--out", str(tmp_path)])
    assert stop.value.code == 2
    assert not (tmp_path / "captures").exists()
