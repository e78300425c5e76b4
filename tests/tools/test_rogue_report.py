"""tools/rogue.py as a process: stopped before its ``--duration`` (as the harness stops a
rogue that overran its time), it still writes its report, marked ``cut_short``."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

from tools.harness.procs import ROOT, free_port


def test_a_rogue_stopped_early_still_reports(tmp_path: Path) -> None:
    out = tmp_path / "rogue.json"
    cmd = [sys.executable, "-m", "tools.rogue", "--connect", f"tcp/127.0.0.1:{free_port()}",
           "--plain-links", "--duration", "60", "--flood", "10", "--json", str(out)]  # fmt: skip
    p = subprocess.Popen(
        cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
    )
    try:
        assert p.stderr is not None
        for line in p.stderr:  # it says when its attack begins (EOF if it ended first)
            if line.startswith("rogue: attacking as stranger"):
                break
        p.send_signal(signal.SIGTERM)
        p.wait(30)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 0
    report = json.loads(out.read_text())
    assert report["connected"] is True and report["cut_short"] is True
    assert report["commands_executed"] == 0 and report["claims_granted"] == 0
