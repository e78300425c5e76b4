"""Rendering in worker processes gives the world's own pictures (sim/server/render_pool.py)."""

from __future__ import annotations

import math
import queue

import numpy as np
import pytest

from agent.wire.picture import picture_of
from sim.physics.world import World
from sim.scenarios import RobotSpec, Scenario
from sim.server.render_pool import Job, RenderPool, Result

NORTH = math.pi / 2


def _scenario() -> Scenario:
    return Scenario(
        robots=(RobotSpec(1, 0.0, 0.0), RobotSpec(2, 0.1, 0.7), RobotSpec(3, -0.6, 0.9)),
        seed=5,
    )


def test_pool_pictures_equal_in_process_renders() -> None:
    results: queue.Queue[Result] = queue.Queue()
    pool = RenderPool(_scenario(), 2, results.put)
    try:
        poses = {1: (0.0, 0.0, NORTH), 2: (0.1, 0.7, -1.0), 3: (-0.6, 0.9, 2.0)}
        heads = {1: 0.0, 2: 0.8, 3: -0.4}
        jobs = [Job(k, 1, yaw, poses, heads) for k, yaw in enumerate((0.0, 0.3, -0.5, 1.2))]
        for job in jobs:
            pool.submit(job)
        got: dict[int, bytes] = {}
        while len(got) < len(jobs):
            res = results.get(timeout=120.0)
            pool.worker_done(res)
            assert res.error == ""
            got[res.job_id] = res.data
        with World(_scenario(), noise=False) as w:
            for rid, (x, y, th) in poses.items():
                w.set_pose(rid, x, y, th)
            for rid, h in heads.items():
                w.set_head_yaw(rid, h)
            for job in jobs:
                want = w.render(1, job.yaw)
                img = picture_of("bgr8", 640, 480, got[job.job_id])
                assert np.array_equal(img, want)
    finally:
        pool.close()


def test_a_bad_job_gets_an_error_and_the_worker_goes_on() -> None:
    results: queue.Queue[Result] = queue.Queue()
    pool = RenderPool(_scenario(), 1, results.put)
    try:
        poses = {1: (0.0, 0.0, NORTH)}
        pool.submit(Job(0, 1, math.radians(150.0), poses, {}))
        pool.submit(Job(1, 1, 0.0, poses, {}))
        first = results.get(timeout=120.0)
        pool.worker_done(first)
        second = results.get(timeout=120.0)
        pool.worker_done(second)
        assert first.job_id == 0 and "outside" in first.error
        assert second.job_id == 1 and second.error == "" and len(second.data) == 640 * 480 * 3
    finally:
        pool.close()


def test_pool_size_is_checked() -> None:
    with pytest.raises(ValueError, match="render workers"):
        RenderPool(_scenario(), 0, lambda r: None)
