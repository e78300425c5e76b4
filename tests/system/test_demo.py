"""The 3-robot demo as real processes (world + 3 agents over loopback), end to end.

Runs ``python -m tools.demo`` exactly as ``make demo`` does (agents claim their robots
with ``--id auto``), then checks the printed table, the result JSON, the figure and the
MCAP recording, and replays the recording with ``python -m tools.replay``. Bounded:
the demo's own limits stop every process well inside the test timeout.

The first demo (TLS, as ``make demo`` runs) is the fast tier's run end to end; the demo
with ``--body naoqi`` is a second whole-fleet run and waits for CI's slow tier.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from agent.phases.reporting import STATUS_MIN_INTERVAL, Phase

pytestmark = pytest.mark.system

ROOT = Path(__file__).resolve().parents[2]


def run(cmd: list[str], timeout: float) -> subprocess.CompletedProcess[str]:
    return subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=timeout)


def test_three_robot_demo_builds_the_pyramid(tmp_path: Path) -> None:
    out = tmp_path / "demo"
    res = run(
        [sys.executable, "-m", "tools.demo", "--robots", "3", "--seed", "1", "--out", str(out),
         "--json", str(tmp_path / "result.json"), "--auto-ids", "--timeout", "240"],
        timeout=290,
    )  # fmt: skip
    report = res.stdout
    assert "child parent" in report and "identical plan digests" in report, res.stderr[-2000:]
    r = json.loads((tmp_path / "result.json").read_text())
    # the processes: every agent claimed a distinct robot and exited 0 after holding
    assert r["claimed_ids"] == [1, 2, 3]
    assert r["exit_codes"] == {"1": 0, "2": 0, "3": 0}, r.get("errors")
    assert set(r["final_phase"].values()) == {"done"}
    # agreement: one plan, and the evaluator computes the same plan from the records
    assert r["identical_digests"] is True
    assert r["evaluator_plan_digest"] == r["plan_digests"]["1"]
    # the pyramid from ground truth: 2 child-parent pairs within the paper's tolerance
    assert len(r["pairs"]) == 2
    for p in r["pairs"]:
        assert abs(p["r_d"]) <= 0.125 and abs(p["r_phi"]) <= 0.30, p
    assert r["contacts"] == 0 and r["min_separation"] > 0.4
    # communication: one exchange, a few re-sends. Statuses are for viewers and keep their
    # pace (agent/phases/reporting.py): one per phase, a repeat when a member reappears,
    # else at most one per STATUS_MIN_INTERVAL, so their bytes follow the run's length (a
    # loaded machine's longer run sends more; ~440 B each here, bounded at 700)
    pace = len(Phase) + 2 + r["wall_total"] / STATUS_MIN_INTERVAL
    for i in ("1", "2", "3"):
        assert 0 < r["exchange_bytes"][i] < 3000
        assert r["bytes"][i]["status"] < 700 * pace, (r["bytes"][i], r["wall_total"])
        assert r["bytes"][i]["total"] == r["exchange_bytes"][i] + r["bytes"][i]["status"]
    assert r["success"] is True and res.returncode == 0
    assert "RESULT: SUCCESS" in report
    fig = out / "formation.png"
    assert fig.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # camera frames for viewers: on in the demo, bounded, apart from the bytes above
    for i in ("1", "2", "3"):
        cam = r["camera"][i]
        assert cam["frames"] >= 3 and cam["bytes"] < 32_768 * cam["frames"], cam
        assert cam["frames_per_s"] <= 2.0 + 1e-6, cam
    check_recording_schemas(out / "run.mcap")
    # the recording replays: timeline with every phase of every agent, and a picture
    rep = run([sys.executable, "-m", "tools.replay", str(out / "run.mcap"), "--frames", "2"], 60)
    assert rep.returncode == 0, rep.stderr[-2000:]
    for rid in (1, 2, 3):
        for phase in ("search", "exchange", "plan", "move", "hold", "done"):
            assert f"robot {rid}: {phase}" in rep.stdout, (rid, phase)
    assert "0 rejected" in rep.stdout
    assert (out / "replay" / "replay.png").stat().st_size > 0
    assert (out / "replay" / "frame-001.png").stat().st_size > 0


def check_recording_schemas(path: Path) -> None:
    """The schema test of the recording: ``run.mcap`` holds Foxglove's scene, image and log
    channels, each with messages, and the annotations of every robot's camera."""
    from collections import Counter

    from mcap.reader import make_reader

    schemas: dict[str, str] = {}
    counts: Counter[str] = Counter()
    with path.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        for ch_id, channel in summary.channels.items():
            schema = summary.schemas[channel.schema_id]
            schemas[channel.topic] = schema.name
            counts[channel.topic] = summary.statistics.channel_message_counts.get(ch_id, 0)
            if schema.name.startswith("foxglove."):
                assert (schema.encoding, channel.message_encoding) == ("jsonschema", "json")
    by_schema: Counter[str] = Counter()
    for topic, name in schemas.items():
        by_schema[name] += counts[topic]
    for name in ("foxglove.SceneUpdate", "foxglove.CompressedImage", "foxglove.Log"):
        assert by_schema[name] > 0, (name, dict(by_schema))
    assert by_schema["foxglove.FrameTransform"] > 0 and by_schema["foxglove.ImageAnnotations"] > 0
    for rid in (1, 2, 3):
        assert schemas[f"/nao/{rid}/camera"] == "foxglove.CompressedImage"
        assert schemas[f"/nao/{rid}/camera/annotations"] == "foxglove.ImageAnnotations"
        assert counts[f"/nao/{rid}/camera"] == counts[f"/nao/{rid}/camera/annotations"] > 0
    assert counts["/scene"] > 0 and counts["/log"] > 0
    # the channels tools.replay reads are still there
    assert counts["world/truth/poses"] > 0 and all(counts[f"nao/{i}/status"] for i in (1, 2, 3))


@pytest.mark.slow
def test_three_robot_demo_with_body_naoqi(tmp_path: Path) -> None:
    """``tools.demo --body naoqi``: the world serves its robots as virtual NAOs over the qi
    protocol; each agent drives its NAO through ALMotion/ALVideoDevice/ALRobotPosture
    and talks zenoh to the others only. With ``--no-publish-camera``, as a real fleet
    runs by default: no camera frame on the bus."""
    out = tmp_path / "demo"
    res = run(
        [sys.executable, "-m", "tools.demo", "--body", "naoqi", "--robots", "3", "--seed", "1",
         "--out", str(out), "--json", str(tmp_path / "result.json"), "--timeout", "240",
         "--no-publish-camera"],
        timeout=290,
    )  # fmt: skip
    assert "identical plan digests" in res.stdout, res.stderr[-2000:]
    world_log = (out / "world.log").read_text()
    urls = [ln for ln in world_log.splitlines() if ln.startswith("sim naoqi robot=")]
    assert len(urls) == 3 and all("url=tcp://127.0.0.1:" in u for u in urls), world_log[-2000:]
    r = json.loads((tmp_path / "result.json").read_text())
    assert r["exit_codes"] == {"1": 0, "2": 0, "3": 0}, r.get("errors")
    assert set(r["final_phase"].values()) == {"done"}
    assert r["identical_digests"] is True
    assert len(r["pairs"]) == 2
    for p in r["pairs"]:
        assert abs(p["r_d"]) <= 0.125 and abs(p["r_phi"]) <= 0.30, p
    assert r["contacts"] == 0
    assert r["success"] is True and res.returncode == 0
    # the world was driven through qi alone: the agents asked the world nothing over zenoh
    # (the virtual NAOs' requests are counted by the world like any other)
    assert "served camera=" in world_log
    for i in (1, 2, 3):
        log = (out / f"agent-{i}.log").read_text()
        assert f"robot {i} exit 0" in log, log[-2000:]
        assert "terminate called" not in log
        assert "camera" not in log.split(f"robot {i} exit 0")[1].split(", compass")[0]
    assert r["camera"] == {}


def test_demo_rejects_bad_arguments() -> None:
    res = run([sys.executable, "-m", "tools.demo", "--robots", "0"], 30)
    assert res.returncode == 2 and "--robots" in res.stderr
    res = run([sys.executable, "-m", "tools.demo", "--body", "naoqi", "--auto-ids"], 30)
    assert res.returncode == 2 and "--auto-ids" in res.stderr


def test_replay_of_a_missing_file_fails_cleanly(tmp_path: Path) -> None:
    res = run([sys.executable, "-m", "tools.replay", str(tmp_path / "none.mcap")], 30)
    assert res.returncode == 2 and "no such file" in res.stderr


def test_replay_of_a_corrupt_file_fails_cleanly(tmp_path: Path) -> None:
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"\x89MCAP0\r\n" + b"garbage" * 10)
    res = run([sys.executable, "-m", "tools.replay", str(bad)], 30)
    assert res.returncode == 1 and "cannot read" in res.stderr
