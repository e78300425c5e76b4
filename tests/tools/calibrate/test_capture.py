"""Capture: every view of the plan taken, NAO-j turned to its orientations and measured by
its compass, a capture stopped half-way resumed where it stopped, the folder's records."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from agent.core.perception.camera import CameraModel
from sim.physics.world import World
from tests.tools.calibrate.conftest import SMALL, Hand, take
from tools.calibrate.capture import TOLERANCE_DEG, Placement, console_prompt, wrap_deg
from tools.calibrate.folder import JOURNAL, CaptureFolder
from tools.calibrate.plan import PlanSpec


def test_every_view_is_taken_with_its_image_and_manifest(captures: Path) -> None:
    cf = CaptureFolder.load(captures)
    shots = SMALL.shots()
    assert sorted(cf.records) == sorted(s.id for s in shots)
    doc = json.loads((captures / "manifest.json").read_text())
    assert len(doc["shots"]) == len(shots) and doc["robots"]["subject"]["id"] == 2
    assert doc["camera"]["width"] == 640 and doc["plan"] == SMALL.to_dict()
    assert (captures / "contact_sheet.png").stat().st_size > 10_000
    for r in cf.taken():
        assert cf.image(r).shape == (480, 640, 3)
        if r.shot.kind != "none":
            # NAO-j turned itself (with the world's motion noise) and measured it
            assert abs(wrap_deg(r.orientation_deg - r.shot.orientation_deg)) <= 2 * TOLERANCE_DEG
    assert {r.orientation_source for r in cf.taken()} <= {"plan", "compass"}


def test_a_stopped_capture_resumes_where_it_stopped(world: World, tmp_path: Path) -> None:
    spec = PlanSpec(
        step_deg=180.0, head_every_deg=360.0, head_yaws_deg=(), side=False,
        distances=(0.5, 1.0, 1.5), dbase_step_deg=180.0, dbase_poses=False,
        check_distances=(), negatives=0,
    )  # fmt: skip
    placements = len({s.placement for s in spec.shots()})

    class StopOnSecond(Hand):
        def __call__(self, p: Placement) -> None:
            if len(self.placements) == 1:
                raise KeyboardInterrupt
            super().__call__(p)

    with pytest.raises(KeyboardInterrupt):
        take(world, tmp_path, spec, StopOnSecond(world))
    first = CaptureFolder.load(tmp_path)
    assert 0 < len(first.records) < len(spec.shots())
    # a line torn by the crash is not a record
    with open(tmp_path / JOURNAL, "a") as f:
        f.write('{"id": "d00009", "set": "db')
    again = Hand(world)
    done = take(world, tmp_path, spec, again)
    assert len(done.records) == len(spec.shots())
    assert len(again.placements) == placements - 1  # the first placement was finished
    nothing = Hand(world)
    take(world, tmp_path, spec, nothing)
    assert nothing.placements == []


def test_another_plan_in_the_same_folder_is_refused(captures: Path) -> None:
    with pytest.raises(ValueError, match="another plan"):
        CaptureFolder.create_or_resume(captures, PlanSpec(), {}, CameraModel())


def test_a_folder_without_a_manifest_is_not_a_capture(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="not a capture folder"):
        CaptureFolder.load(tmp_path)
    (tmp_path / "manifest.json").write_text('{"version": 9}')
    with pytest.raises(ValueError, match="version 9"):
        CaptureFolder.load(tmp_path)


def test_the_prompt_says_where_and_end_of_input_stops(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    p = Placement("dbase", 1, 2, 1.25, -90.0)
    assert "90° to the right of NAO-i (robot 1)" in p.text() and "1.25 m" in p.text()
    assert "straight ahead" in Placement("mbase", 1, 2, 0.6, 0.0).text()

    def no_input(prompt: str = "") -> str:
        raise EOFError

    monkeypatch.setattr("builtins.input", no_input)
    with pytest.raises(KeyboardInterrupt):
        console_prompt(p)
    assert "Place NAO-j (robot 2)" in capsys.readouterr().err


def test_wrap_deg() -> None:
    assert wrap_deg(190.0) == pytest.approx(-170.0)
    assert wrap_deg(-180.0) == pytest.approx(180.0)
    assert wrap_deg(359.0) == pytest.approx(-1.0)
