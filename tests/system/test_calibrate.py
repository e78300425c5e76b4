"""``python -m tools.calibrate rehearse``: capture, build and check over the real qi protocol
against virtual NAOs (the simulated world and its qi gateway), on a coarse grid; the
calibration folder it leaves is one the agent loads."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from agent.core.perception.calibration import builtin, load
from tools.calibrate.folder import CaptureFolder
from tools.calibrate.plan import coarse

pytestmark = [pytest.mark.system, pytest.mark.slow]
ROOT = Path(__file__).resolve().parents[2]


def test_rehearse_leaves_a_checked_calibration(tmp_path: Path) -> None:
    out = tmp_path / "rehearsal"
    res = subprocess.run(
        [sys.executable, "-m", "tools.calibrate", "rehearse", "--look", "default",
         "--grid", "coarse", "--out", str(out)],
        cwd=ROOT, capture_output=True, text=True, timeout=900,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr[-3000:]
    cal = load(out / "calibration")
    assert cal.digest != builtin().digest
    assert f"calibration {cal.digest}" in res.stdout
    report = json.loads((out / "calibration" / "report" / "check.json").read_text())
    assert report["failed"] == [] and report["positives"] >= 10
    caps = CaptureFolder.load(out / "captures")
    assert len(caps.records) == len(coarse().shots())
    assert caps.header["robots"]["observer"]["url"].startswith("tcp://127.0.0.1:")
    assert caps.header["look"] == "default"
    assert (out / "captures" / "contact_sheet.png").is_file()


def test_a_look_the_world_cannot_render_is_refused(tmp_path: Path) -> None:
    """A malformed look is refused before anything starts (argparse's exit 2)."""
    from tools.calibrate import __main__ as cli

    with pytest.raises(SystemExit) as stop:
        cli.main(["rehearse", "--look", "hue:abc", "--out", str(tmp_path)])
    assert stop.value.code == 2
    assert not (tmp_path / "captures").exists()
