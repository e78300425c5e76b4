"""The recording that Foxglove opens: a fake observer stream written by the
recorder and read back with ``mcap``'s reader (tools/harness/observe.py ``Recorder``,
tools/harness/view/scene.py, tools/harness/view/foxglove.py)."""

from __future__ import annotations

import json
import math
import os
from collections import defaultdict
from pathlib import Path
from typing import Any

import pytest

from agent.adapters import FormationAdapter
from agent.core.formation.params import PlanParams
from agent.wire import (
    CameraDetection,
    CameraMsg,
    ContactMsg,
    DigestMsg,
    NeighborRecordMsg,
    StatusMsg,
    TruthPosesMsg,
    encode,
)
from tests.tools.fleet6 import ideal_records
from tools.harness.observe import Observer, Recorder
from tools.harness.view import foxglove as fg
from tools.harness.view.scene import Scene, to_world

NORTH = math.pi / 2
WORLD = {1: (1.0, 2.0), 2: (2.0, 2.2), 3: (1.4, 3.1)}  # aligned starts (world m)


def records() -> tuple[NeighborRecordMsg, ...]:
    """Ideal records of the aligned fleet WORLD: each robot sees every other."""
    return ideal_records(WORLD)


def truth(t: float, dx: float = 0.0) -> TruthPosesMsg:
    return TruthPosesMsg(
        t_sim=t, poses=tuple((i, x + dx, y, NORTH) for i, (x, y) in sorted(WORLD.items()))
    )


def feed(rec: Recorder, digest: str) -> Observer:
    """A short run as the observer sees it: truth, exchange, a plan, motion, a contact,
    a failure."""
    obs = Observer(0.0)
    take = obs.take
    take("world/truth/poses", truth(0.5), rec)
    for i in WORLD:
        take(f"nao/{i}/status", StatusMsg(sender=i, phase="exchange", t_sim=0.5), rec)
    for r in records():
        take(f"nao/{r.sender}/record", r, rec)
        take(f"nao/{r.sender}/record", r, rec)  # re-published: logged once
    for i in WORLD:
        take(
            f"nao/{i}/digest",
            DigestMsg(sender=i, round=0, digest="ab" * 32, members=(1, 2, 3)),
            rec,
        )
    take("world/truth/poses", truth(1.0), rec)
    for i in WORLD:
        take(f"nao/{i}/status", StatusMsg(sender=i, phase="plan", plan_digest=digest), rec)
        st = StatusMsg(sender=i, phase="move", wave=0, plan_digest=digest, detail="leg 1")
        take(f"nao/{i}/status", st, rec)
        take(f"nao/{i}/status", st, rec)  # no change: one log line
    take("world/truth/poses", truth(2.0, dx=0.1), rec)
    take("world/truth/contacts", ContactMsg(t_sim=2.0, a=1, b=-1), rec)
    failed = StatusMsg(sender=3, phase="failed", error="AgentFailure: lost its parent")
    take("nao/3/status", failed, rec)
    return obs


def read(path: Path) -> tuple[dict[str, Any], dict[str, list[tuple[int, Any]]]]:
    """(channels by topic: (schema name, schema encoding, message encoding, schema data),
    messages by topic: (log time, decoded JSON or raw bytes))."""
    from mcap.reader import make_reader

    chans: dict[str, Any] = {}
    msgs: dict[str, list[tuple[int, Any]]] = defaultdict(list)
    with path.open("rb") as f:
        for schema, channel, message in make_reader(f).iter_messages(log_time_order=True):
            assert schema is not None
            chans[channel.topic] = (
                schema.name,
                schema.encoding,
                channel.message_encoding,
                schema.data,
            )
            body = json.loads(message.data) if channel.message_encoding == "json" else message.data
            msgs[channel.topic].append((message.log_time, body))
    return chans, msgs


def conforms(value: Any, schema: dict[str, Any], where: str = "$") -> None:
    """A small JSON Schema check (type, properties, required, items, oneOf of consts)."""
    if "oneOf" in schema:
        assert value in [c["const"] for c in schema["oneOf"]], where
        return
    kind = schema.get("type")
    if kind == "object":
        assert isinstance(value, dict), where
        assert set(schema.get("required", [])) <= set(value), (where, sorted(value))
        for k, v in value.items():
            assert k in schema["properties"], f"{where}.{k} is not in the schema"
            conforms(v, schema["properties"][k], f"{where}.{k}")
    elif kind == "array":
        assert isinstance(value, list), where
        for k, v in enumerate(value):
            conforms(v, schema["items"], f"{where}[{k}]")
    elif kind == "number":
        assert isinstance(value, int | float) and math.isfinite(value), where
    elif kind == "integer":
        assert isinstance(value, int) and value >= schema.get("minimum", value), where
    elif kind == "string":
        assert isinstance(value, str), where
    elif kind == "boolean":
        assert isinstance(value, bool), where


@pytest.fixture
def recording(tmp_path: Path) -> tuple[dict[str, Any], dict[str, list[tuple[int, Any]]], str]:
    plan = FormationAdapter().plan(records(), PlanParams())
    rec = Recorder(tmp_path / "run.mcap")
    obs = feed(rec, str(plan.digest))
    rec.close()
    assert obs.rejected == 0 and rec.scene_rejected == 0
    chans, msgs = read(tmp_path / "run.mcap")
    return chans, msgs, str(plan.digest)


def test_schemas_are_registered_with_foxglove_names_and_json_encodings(recording: Any) -> None:
    chans, msgs, _ = recording
    expect = {
        "/scene": "foxglove.SceneUpdate",
        "/scene/plan": "foxglove.SceneUpdate",
        "/tf": "foxglove.FrameTransform",
        "/log": "foxglove.Log",
        "/robots/1/status": "nao.Status",
    }
    for topic, name in expect.items():
        schema_name, schema_enc, msg_enc, data = chans[topic]
        assert (schema_name, schema_enc, msg_enc) == (name, "jsonschema", "json")
        schema = json.loads(data)
        assert schema["title"] == name
        for _, body in msgs[topic]:
            conforms(body, schema)
    assert "/scene/obstacles" not in chans  # no obstacles in this world
    # the raw wire channels stay, msgpack, byte for byte
    assert chans["nao/1/status"][2] == "msgpack"
    assert msgs["world/truth/poses"][0][1] == encode(truth(0.5))


def test_log_times_are_world_times(recording: Any) -> None:
    _, msgs, _ = recording
    assert [t for t, _ in msgs["/scene"]] == [500_000_000, 1_000_000_000, 2_000_000_000]
    for t, body in msgs["/scene"]:
        assert body["entities"][0]["timestamp"] == fg.stamp(t)
    assert msgs["nao/1/status"][0][0] == 500_000_000  # raw channels too
    assert msgs["world/truth/poses"][-1][0] == 2_000_000_000


def test_scene_draws_every_robot_from_the_ground_truth(recording: Any) -> None:
    _, msgs, _ = recording
    last = msgs["/scene"][-1][1]["entities"]
    assert [e["id"] for e in last] == ["robot/1", "robot/2", "robot/3"]
    body = last[0]["cylinders"][0]
    assert body["pose"]["position"]["x"] == pytest.approx(1.1)
    assert body["pose"]["position"]["y"] == pytest.approx(2.0)
    assert last[0]["texts"][0]["text"] == "1 move w0"
    q = last[0]["arrows"][0]["pose"]["orientation"]
    assert 2 * math.atan2(q["z"], q["w"]) == pytest.approx(NORTH)
    tf = [b for _, b in msgs["/tf"] if b["child_frame_id"] == "robot/2"]
    assert len(tf) == 3 and tf[-1]["translation"]["x"] == pytest.approx(2.1)


def test_plan_is_drawn_in_the_world_when_its_digest_was_reported(recording: Any) -> None:
    _, msgs, digest = recording
    plan = FormationAdapter().plan(records(), PlanParams())
    [(t, update)] = msgs["/scene/plan"]
    assert t == 1_000_000_000  # the world time of the first status that reported it
    ents = {e["id"]: e for e in update["entities"]}
    frame = (*WORLD[int(plan.frame_robot)], NORTH)
    for rp in plan.robots:
        e = ents[f"plan/robot/{rp.robot_id}"]
        x, y = to_world(rp.target, frame)
        pos = e["cylinders"][0]["pose"]["position"]
        assert (pos["x"], pos["y"]) == pytest.approx((x, y), abs=1e-4)
        assert len(e["lines"][0]["points"]) == len(rp.path())
    links = ents["plan/links"]["lines"][0]
    assert links["type"] == fg.LINE_TYPES.index("LINE_LIST")
    assert len(links["points"]) == 2 * sum(1 for rp in plan.robots if rp.parent >= 0)
    common = [b for _, b in msgs["/tf"] if b["child_frame_id"] == "common"]
    assert len(common) == 1 and common[0]["translation"]["x"] == pytest.approx(frame[0])
    notes = [b["message"] for _, b in msgs["/log"] if b["name"] == "recorder"]
    assert notes == [f"plan {digest[:12]} drawn: leader {plan.leader}, frame robot "
                     f"{plan.frame_robot}, {len(plan.waves)} waves, excluded []"]  # fmt: skip


def test_log_has_every_status_change_and_the_failure_reason(recording: Any) -> None:
    _, msgs, _ = recording
    lines = [(b["level"], b["name"], b["message"]) for _, b in msgs["/log"]]
    robot1 = [(lv, m) for lv, n, m in lines if n == "robot 1"]
    assert [m.split(":")[0] for lv, m in robot1 if lv == fg.INFO] == [
        "exchange", "plan", "move (wave 0)",
    ]  # fmt: skip
    assert sum(1 for lv, m in robot1 if lv == fg.DEBUG and m.startswith("record")) == 1
    assert (fg.ERROR, "robot 3", "failed: AgentFailure: lost its parent") in lines
    assert any(n == "world" and lv == fg.WARNING and "CONTACT" in m for lv, n, m in lines)
    assert len(msgs["/robots/3/status"]) == 5  # every status, as JSON
    assert msgs["/robots/3/status"][-1][1]["error"] == "AgentFailure: lost its parent"


def test_replay_reads_only_the_wire_channels(tmp_path: Path) -> None:
    from tools.replay import load

    rec = Recorder(tmp_path / "run.mcap")
    feed(rec, "cd" * 32)
    rec.close()
    rp = load(tmp_path / "run.mcap")
    assert rp.rejected == 0 and rp.messages == rec.count - sum(1 for _ in _json_messages(tmp_path))
    assert len(rp.truth) == 3
    assert all(t >= 0.0 for t, _ in rp.events)


def _json_messages(tmp_path: Path) -> list[int]:
    chans, msgs = read(tmp_path / "run.mcap")
    return [1 for topic, ms in msgs.items() for _ in ms if chans[topic][2] == "json"]


# ===================================================================== error branches


def notes(path: Path) -> list[tuple[int, str]]:
    _, msgs = read(path)
    return [(b["level"], b["message"]) for _, b in msgs["/log"] if b["name"] == "recorder"]


def test_no_reported_plan_draws_none(tmp_path: Path) -> None:
    rec = Recorder(tmp_path / "run.mcap")
    rec.record("world/truth/poses", truth(0.5))
    rec.close()
    assert notes(tmp_path / "run.mcap") == [(fg.INFO, "no agent reported a plan: no plan drawn")]
    [(t, _)] = [m for m in read(tmp_path / "run.mcap")[1]["/log"]]
    assert t == 500_000_000  # at the end of the run


def test_plan_of_other_parameters_is_not_drawn(tmp_path: Path) -> None:
    rec = Recorder(tmp_path / "run.mcap", params=PlanParams(d_e=1.1))
    digest = str(FormationAdapter().plan(records(), PlanParams()).digest)
    feed(rec, digest)
    rec.close()
    [(level, text)] = notes(tmp_path / "run.mcap")
    assert level == fg.WARNING and f"the agents reported {digest[:12]}" in text
    assert "/scene/plan" not in read(tmp_path / "run.mcap")[0]


def test_plan_that_cannot_be_computed_is_not_drawn(tmp_path: Path) -> None:
    rec = Recorder(tmp_path / "run.mcap")
    rec.record("world/truth/poses", truth(0.5))
    rec.record("nao/1/status", StatusMsg(sender=1, phase="plan", plan_digest="ef" * 32))
    rec.close()  # no record at all: the planner has nothing to plan from
    [(level, text)] = notes(tmp_path / "run.mcap")
    assert level == fg.WARNING and text.startswith("plan not drawn: ")


def test_plan_without_ground_truth_is_not_drawn(tmp_path: Path) -> None:
    plan = FormationAdapter().plan(records(), PlanParams())
    rec = Recorder(tmp_path / "run.mcap")
    for r in records():
        rec.record(f"nao/{r.sender}/record", r)
    rec.record("nao/1/status", StatusMsg(sender=1, phase="plan", plan_digest=str(plan.digest)))
    rec.close()  # no truth sample ever came
    [(level, text)] = notes(tmp_path / "run.mcap")
    assert level == fg.WARNING and "no planned robot has a true start" in text


def test_world_obstacles_from_this_runs_scenario_file(tmp_path: Path) -> None:
    from sim import scenarios

    rec = Recorder(tmp_path / "run.mcap")
    sc = scenarios.generate(3, 1, obstacles=2)
    scenarios.dump(sc, tmp_path / "scenario.json")  # written after the recorder started
    rec.record("world/truth/poses", truth(0.5))
    rec.record("world/truth/poses", truth(1.0))
    rec.close()
    [(_, update)] = read(tmp_path / "run.mcap")[1]["/scene/obstacles"]
    cyl = update["entities"][0]["cylinders"]
    assert [(c["pose"]["position"]["x"], c["size"]["x"]) for c in cyl] == [
        (pytest.approx(o.x), pytest.approx(2 * o.radius)) for o in sc.obstacles
    ]


def test_an_older_runs_scenario_file_is_ignored(tmp_path: Path) -> None:
    from sim import scenarios

    scenarios.dump(scenarios.generate(3, 1, obstacles=2), tmp_path / "scenario.json")
    os.utime(tmp_path / "scenario.json", ns=(0, 0))
    rec = Recorder(tmp_path / "run.mcap")
    rec.record("world/truth/poses", truth(0.5))
    rec.close()
    assert "/scene/obstacles" not in read(tmp_path / "run.mcap")[0]


def test_a_broken_scenario_file_is_said_in_the_log(tmp_path: Path) -> None:
    rec = Recorder(tmp_path / "run.mcap")
    (tmp_path / "scenario.json").write_text("{not json")
    rec.record("world/truth/poses", truth(0.5))
    rec.close()
    assert notes(tmp_path / "run.mcap")[0][1].startswith("world obstacles not drawn: ")


def test_given_obstacles_are_drawn(tmp_path: Path) -> None:
    rec = Recorder(tmp_path / "run.mcap", obstacles=[(0.5, 0.5, 0.15)])
    rec.record("world/truth/poses", truth(0.5))
    rec.close()
    [(t, update)] = read(tmp_path / "run.mcap")[1]["/scene/obstacles"]
    assert t == 500_000_000 and len(update["entities"][0]["cylinders"]) == 1


def test_a_failing_view_never_costs_a_raw_message(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    def boom(*a: Any) -> None:
        raise ValueError("x" * 5000)

    rec = Recorder(tmp_path / "run.mcap")
    monkeypatch.setattr(rec.scene, "take", boom)
    monkeypatch.setattr(rec.scene, "finish", boom)
    rec.record("world/truth/poses", truth(0.5))
    rec.close()
    assert rec.scene_rejected == 2
    chans, msgs = read(tmp_path / "run.mcap")
    assert list(chans) == ["world/truth/poses"] and len(msgs["world/truth/poses"]) == 1
    err = capsys.readouterr().err
    assert "ValueError" in err and max(len(x) for x in err.splitlines()) < 400


def test_a_value_json_cannot_carry_is_refused_by_the_view(tmp_path: Path) -> None:
    rec = Recorder(tmp_path / "run.mcap")
    rec.scene.emit("/log", fg.LOG, fg.log(0, fg.INFO, "x", "ok"), 0)
    with pytest.raises(ValueError):
        rec.scene.emit("/log", fg.LOG, {"level": math.nan}, 0)
    rec.close()


def test_builders_refuse_what_foxglove_does_not_know() -> None:
    with pytest.raises(ValueError, match="primitive"):
        fg.entity(0, "x", boxes=[])
    with pytest.raises(ValueError, match="log level"):
        fg.log(0, 9, "x", "y")


# ===================================================================== parts


def test_common_frame_to_world_turns_by_the_frame_robots_heading() -> None:
    assert to_world((0.0, 0.0), (1.0, 2.0, 0.3)) == pytest.approx((1.0, 2.0))
    # the common frame's +y is the frame robot's forward
    h = 0.7
    assert to_world((0.0, 1.0), (1.0, 2.0, h)) == pytest.approx((1 + math.cos(h), 2 + math.sin(h)))
    assert to_world((1.0, 0.0), (0.0, 0.0, NORTH)) == pytest.approx((1.0, 0.0))


def test_every_schema_is_a_closed_json_schema() -> None:
    names = set(fg.SCHEMAS)
    assert names == {
        "foxglove.SceneUpdate", "foxglove.Log", "foxglove.FrameTransform",
        "foxglove.CompressedImage", "foxglove.ImageAnnotations",
    }  # fmt: skip
    for schema in fg.SCHEMAS.values():
        json.loads(json.dumps(schema))
    image = {"timestamp": fg.stamp(1), "frame_id": "cam", "data": "AAEC", "format": "jpeg"}
    conforms(image, fg.COMPRESSED_IMAGE)
    conforms({"circles": [], "points": [], "texts": []}, fg.IMAGE_ANNOTATIONS)
    assert fg.stamp(-5) == {"sec": 0, "nsec": 0}
    assert fg.stamp(3_000_000_007) == {"sec": 3, "nsec": 7}


def test_scene_alone_emits_to_any_sink() -> None:
    out: list[tuple[str, str]] = []
    scene = Scene(lambda topic, schema, message, t_ns: out.append((topic, schema["title"])))
    scene.take("world/truth/poses", truth(0.5), 500)
    assert out == [("/scene", "foxglove.SceneUpdate")] + [("/tf", "foxglove.FrameTransform")] * 3


def viewer_accepts(schema: dict[str, Any], where: str = "$") -> None:
    """The rules by which Foxglove and Lichtblick turn a JSON Schema into message
    definitions (their mcap-support ``parseJsonSchema``): an object schema whose every
    property is an enum of number constants, a boolean, number, integer, string (plain or
    base64), object (the same rules) or array of those (base64 strings excepted)."""
    assert schema.get("type") == "object", where
    for name, field in schema["properties"].items():
        at = f"{where}.{name}"
        if "oneOf" in field:
            assert all(isinstance(alt["const"], int) for alt in field["oneOf"]), at
            continue
        kind = field.get("type")
        if kind == "object":
            viewer_accepts(field, at)
        elif kind == "array":
            item = field["items"]
            assert item.get("type") in ("boolean", "string", "number", "integer", "object"), at
            if item["type"] == "object":
                viewer_accepts(item, at + "[]")
            assert "contentEncoding" not in item, at
        else:
            assert kind in ("boolean", "string", "number", "integer"), at
            assert field.get("contentEncoding") in (None, "base64"), at


def test_the_viewers_accept_every_schema() -> None:
    from tools.harness.view.scene import STATUS

    for schema in [*fg.SCHEMAS.values(), STATUS]:
        viewer_accepts(schema)


def test_the_layout_shows_the_channels_the_recorder_writes(recording: Any) -> None:
    chans, _, _ = recording
    root = Path(__file__).resolve().parents[2]
    layout = json.loads((root / "docs" / "foxglove-layout.json").read_text())
    panels = layout["configById"]
    [three_d] = [v for k, v in panels.items() if k.startswith("3D!")]
    assert set(three_d["topics"]) == {"/scene", "/scene/obstacles", "/scene/plan"}
    assert all(t in chans for t in three_d["topics"] if t != "/scene/obstacles")
    [log_panel] = [v for k, v in panels.items() if k.startswith("RosOut!")]
    assert chans[log_panel["topicToRender"]][0] == "foxglove.Log"
    [raw] = [v for k, v in panels.items() if k.startswith("RawMessages!")]
    assert chans[raw["topicPath"]][2] == "json"

    def leaves(node: Any) -> list[str]:
        return [node] if isinstance(node, str) else leaves(node["first"]) + leaves(node["second"])

    assert sorted(leaves(layout["layout"])) == sorted(panels)


# --------------------------------------------------------------------------- camera frames


def camera(rid: int, t: float, n: int = 1) -> CameraMsg:
    """A camera frame of robot ``rid`` (a real JPEG) with ``n`` detections."""
    import cv2
    import numpy as np

    ok, buf = cv2.imencode(".jpg", np.full((120, 160, 3), 90, np.uint8))
    assert ok
    dets = tuple(
        CameraDetection(id=k, box=(10 + 40 * k, 30, 20, 50), d=1.0 + k, phi=0.1 * k)
        for k in range(n)
    )
    return CameraMsg(
        robot=rid, seq=0, t_sim=t, width=160, height=120, jpeg=buf.tobytes(), yaw=0.5,
        detections=dets,
    )  # fmt: skip


def test_camera_frames_are_images_with_their_detections(tmp_path: Path) -> None:
    import base64

    rec = Recorder(tmp_path / "run.mcap")
    obs = Observer(0.0)
    obs.take("world/truth/poses", truth(0.5), rec)
    frame = camera(2, 0.4, n=2)
    obs.take("nao/2/camera", frame, rec, size=2000)
    obs.take("nao/1/camera", camera(1, 0.4, n=0), rec)
    rec.close()
    assert rec.scene_rejected == 0
    chans, msgs = read(tmp_path / "run.mcap")
    assert chans["/nao/2/camera"][:3] == ("foxglove.CompressedImage", "jsonschema", "json")
    assert chans["/nao/2/camera/annotations"][0] == "foxglove.ImageAnnotations"
    [(t, image)] = msgs["/nao/2/camera"]
    conforms(image, fg.COMPRESSED_IMAGE)
    assert t == 500_000_000 and image["timestamp"] == fg.stamp(t)
    assert (image["format"], image["frame_id"]) == ("jpeg", "nao2/camera")
    assert base64.b64decode(image["data"]) == frame.jpeg
    [(ta, marks)] = msgs["/nao/2/camera/annotations"]
    conforms(marks, fg.IMAGE_ANNOTATIONS)
    assert ta == t and all(b["timestamp"] == image["timestamp"] for b in marks["points"])
    assert [[(p["x"], p["y"]) for p in b["points"]] for b in marks["points"]] == [
        [(10, 30), (30, 30), (30, 80), (10, 80)],
        [(50, 30), (70, 30), (70, 80), (50, 80)],
    ]
    texts = [x["text"] for x in marks["texts"]]
    assert texts == ["nao 2 yaw +29°", "#0 1.00 m", "#1 2.00 m"]
    assert [m[0] for m in msgs["/nao/1/camera/annotations"]] == [t]  # no detections: yaw only
    assert msgs["nao/2/camera"][0][1] == encode(frame)  # the raw wire channel as ever
    # the observer counts the frames apart from the fleet's own bytes
    assert obs.agents[2].camera_frames == 1 and obs.agents[2].camera_bytes == 2000
    assert "camera" not in obs.agents[2].bytes_by_kind


def test_a_camera_frame_on_another_robots_key_is_not_drawn(tmp_path: Path) -> None:
    rec = Recorder(tmp_path / "run.mcap")
    rec.record("nao/1/camera", camera(2, 0.1))
    rec.close()
    assert rec.scene_rejected == 1
    chans, _ = read(tmp_path / "run.mcap")
    assert "nao/1/camera" in chans and "/nao/2/camera" not in chans and "/nao/1/camera" not in chans


def test_camera_rate_per_robot() -> None:
    from tools.harness.judge import camera_rate
    from tools.harness.observe import AgentView

    v = AgentView(camera_frames=21, camera_bytes=100_000, camera_wall=(5.0, 15.0))
    c = camera_rate(v, 50.0)
    assert c == {
        "frames": 21, "bytes": 100_000, "kB_per_s": 10.0, "kB_per_s_run": 2.0,
        "frames_per_s": 2.0,
    }  # fmt: skip
    assert camera_rate(AgentView(), 0.0)["kB_per_s"] == 0.0


def test_the_layout_shows_each_robots_camera_with_its_annotations() -> None:
    root = Path(__file__).resolve().parents[2]
    layout = json.loads((root / "docs" / "foxglove-layout.json").read_text())
    images = [v for k, v in layout["configById"].items() if k.startswith("Image!")]
    assert sorted(v["imageMode"]["imageTopic"] for v in images) == [
        f"/nao/{i}/camera" for i in (1, 2, 3)
    ]
    for v in images:
        topic = v["imageMode"]["imageTopic"]
        assert v["imageMode"]["annotations"] == {f"{topic}/annotations": {"visible": True}}


def test_scene_alone_emits_camera_frames_to_any_sink() -> None:
    out: list[tuple[str, str, int]] = []
    scene = Scene(lambda topic, schema, message, t_ns: out.append((topic, schema["title"], t_ns)))
    scene.take("nao/3/camera", camera(3, 1.0, n=1), 700)
    assert out == [
        ("/nao/3/camera", "foxglove.CompressedImage", 700),
        ("/nao/3/camera/annotations", "foxglove.ImageAnnotations", 700),
    ]
