"""The offline frame evaluation of recorded runs (tools/eval_frames.py)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from agent.wire import NeighborRecordMsg, encode
from tests.formation.pose_fleets import fault, sim_layout, unaligned_records
from tools import eval_frames


def _run(folder: Path, seed: int, faulty: int = -1, bend_truth: float = 0.0) -> None:
    """A run folder as tools.demo leaves it: run.mcap with the records, result.json."""
    from mcap.writer import Writer

    rng = np.random.default_rng(seed)
    ids = [1, 2, 3, 4, 5, 6]
    pos = sim_layout(rng, 6)
    h = rng.uniform(-math.pi, math.pi, 6)
    recs = unaligned_records(ids, pos, h, rng, 0.02, math.radians(1))
    if faulty > 0:
        recs[ids.index(faulty)] = fault(recs[ids.index(faulty)], "scale")
    folder.mkdir(parents=True)
    with (folder / "run.mcap").open("wb") as f:
        w = Writer(f)
        w.start()
        schema = w.register_schema("nao", "", b"")
        for t, r in enumerate(recs):
            assert r.orientations is not None
            msg = NeighborRecordMsg(
                sender=r.robot_id,
                round=0,
                neighbours=tuple((float(x), float(y)) for x, y in r.neighbours),
                orientations=tuple(float(o) for o in np.mod(r.orientations, 2 * math.pi) - math.pi),
            )
            ch = w.register_channel(f"nao/{r.robot_id}/record", "msgpack", schema)
            w.add_message(ch, log_time=t + 1, data=encode(msg), publish_time=t + 1)
        w.finish()
    starts = {str(i): [float(pos[k, 0]), float(pos[k, 1]), float(h[k])] for k, i in enumerate(ids)}
    starts["2"][2] += bend_truth
    args = [f"{faulty}:--sensor-fault=scale:1.4"] if faulty > 0 else []
    (folder / "result.json").write_text(json.dumps({"starts": starts, "agent_args": args}))


def test_sound_and_faulty_runs_are_judged_against_their_truth(tmp_path: Path) -> None:
    _run(tmp_path / "a" / "seed-001", 1)
    _run(tmp_path / "a" / "seed-003", 3, faulty=3)
    out = tmp_path / "rows.json"
    code = eval_frames.main([str(tmp_path), "--png", str(tmp_path / "f.png"), "--json", str(out)])
    rows = json.loads(out.read_text())["rows"]
    assert code == 0 and (tmp_path / "f.png").stat().st_size > 0
    assert [r["faulty"] for r in rows] == [-1, 3]
    assert rows[0]["excluded"] == [] and rows[0]["psi_err"] < 2.0 and rows[0]["pos_err"] < 0.1
    assert rows[1]["excluded"] == [3] and "robot 3 named" in rows[1]["reason"]


def test_a_frame_that_disagrees_with_the_truth_is_bad(tmp_path: Path) -> None:
    _run(tmp_path / "seed-001", 1, bend_truth=math.radians(30))  # robot 2 really faced 30° off
    assert eval_frames.main([str(tmp_path), "--png", str(tmp_path / "f.png")]) == 1


def test_no_runs_and_the_faulty_robot_of_the_arguments(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert eval_frames.main([str(tmp_path)]) == 2
    assert "no run folders" in capsys.readouterr().err
    assert eval_frames.faulty_robot({"agent_args": ["4:--sensor-fault=shift:0.5"]}) == 4
    assert eval_frames.faulty_robot({"agent_args": ["--headings=random"]}) == -1
    assert eval_frames.faulty_robot({}) == -1
