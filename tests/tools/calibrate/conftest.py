"""A small capture folder rendered with the real world: two in-process robots (the bodies of
:mod:`agent.body.in_process`, the same renders and motion noise as the world process)
captured by the real :func:`tools.calibrate.capture.capture`, a person's placements done
by teleporting NAO-j. Four masks 90° apart, four D-base distances, a few held-out views."""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import pytest

from agent.body.in_process import WorldBody
from agent.core.perception.camera import CameraModel
from sim.physics.world import World
from tools.calibrate.capture import Placement, capture
from tools.calibrate.folder import CaptureFolder
from tools.calibrate.plan import PlanSpec
from tools.calibrate.rehearse import make_world

SMALL = PlanSpec(
    step_deg=90.0,
    head_every_deg=180.0,
    head_yaws_deg=(45.0,),
    side=False,
    distances=(0.5, 0.9, 1.6, 2.6),
    dbase_step_deg=90.0,
    dbase_poses=False,
    check_distances=(0.7, 2.0),
    check_step_deg=180.0,
    check_offset_deg=0.0,
    negatives=2,
)


class Hand:
    """Places NAO-j as a person would (the world is this thread's); counts the prompts."""

    def __init__(self, world: World) -> None:
        self.world = world
        self.placements: list[Placement] = []

    def __call__(self, p: Placement) -> None:
        x0, y0, h0 = self.world.pose(p.observer)
        a = h0 + math.radians(p.bearing_deg)
        x, y = x0 + p.distance * math.cos(a), y0 + p.distance * math.sin(a)
        self.world.set_pose(p.subject, x, y, a + math.pi)
        self.placements.append(p)


def take(world: World, path: Path, spec: PlanSpec, prompt: Hand) -> CaptureFolder:
    robots = {"observer": {"id": 1, "url": "in-process"}, "subject": {"id": 2, "url": "in-process"}}
    folder = CaptureFolder.create_or_resume(path, spec, robots, CameraModel())
    return capture(WorldBody(world, 1), WorldBody(world, 2), folder, prompt)


@pytest.fixture(scope="package")
def world() -> Iterator[World]:
    with make_world("default", seed=3) as w:
        yield w


@pytest.fixture(scope="package")
def captures(world: World, tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("captures")
    take(world, path, SMALL, Hand(world))
    return path
