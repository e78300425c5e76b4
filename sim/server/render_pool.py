"""Forehead-camera rendering in worker processes (opt-in: ``python -m sim --render-workers K``).

TinyRenderer is single-threaded and a render is most of a camera request's cost, so
when several agents sweep their heads at once the world serialises them. A pool of K
worker processes, each holding its own copy of the room (built from the same scenario
and seed, hence the same textures), renders K requests at once. A job carries the
complete state a render depends on — every robot's pose and head yaw at the moment the
request was taken — so a worker's picture is exactly what the world would have drawn in
process (the tests compare them pixel for pixel).

Threads: the server's loop sends jobs (it alone writes the job pipes); one reader thread
waits on the result pipes and hands each result to a callback (the server puts it on its
inbox queue, so the loop stays the only owner of the world and of zenoh replies).
"""

from __future__ import annotations

import contextlib
import multiprocessing
import multiprocessing.connection
import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from agent.wire.picture import DEFAULT_ENCODING, picture_data
from sim.camera.picture import Shot
from sim.scenarios import Scenario, from_dict, to_dict


@dataclass(frozen=True)
class Job:
    """One render: robot ``robot_id``'s camera at head ``yaw``, in the state given, as
    picture ``shot`` (numbered by the world, so the look develops it as the world would)."""

    job_id: int
    robot_id: int
    yaw: float
    poses: dict[int, tuple[float, float, float]]
    heads: dict[int, float]
    shot: Shot | None = None


@dataclass(frozen=True)
class Result:
    job_id: int
    worker: int
    data: bytes = b""  # the picture in the pool's encoding (agent.wire.picture)
    error: str = ""
    dead: bool = False  # the worker exited: it takes no more jobs


def _worker(
    index: int, scenario: dict[str, Any], renderer: str, encoding: str, jobs: Any, results: Any
) -> None:
    from sim.physics.world import World

    try:
        world = World(from_dict(scenario), noise=False, renderer=renderer)
    except Exception as exc:  # reported to the parent, which refuses to start
        results.send(("failed", f"{type(exc).__name__}: {exc}"))
        return
    results.send(("ready", index))
    with world:
        while True:
            try:
                job = jobs.recv()
            except EOFError:
                return
            if job is None:
                return
            try:
                for rid, (x, y, th) in job.poses.items():
                    world.set_pose(rid, x, y, th)
                for rid, h in job.heads.items():
                    if rid != job.robot_id:
                        world.set_head_yaw(rid, h)
                img = world.render(job.robot_id, job.yaw, job.shot)
                results.send(Result(job.job_id, index, data=picture_data(img, encoding)))
            except Exception as exc:
                results.send(Result(job.job_id, index, error=f"{type(exc).__name__}: {exc}"))


class RenderPool:
    """K worker processes rendering camera jobs; results go to ``on_result``.

    ``renderer``: the world's (``tiny`` or ``egl``, :mod:`sim.camera.renderer`), so a worker's
    picture is the one the world would draw; ``encoding``: how a result carries it (the
    world's camera encoding, :mod:`agent.wire.picture`)."""

    def __init__(
        self,
        scenario: Scenario,
        workers: int,
        on_result: Callable[[Result], None],
        *,
        start_timeout: float = 120.0,
        renderer: str = "tiny",
        encoding: str = DEFAULT_ENCODING,
    ) -> None:
        if isinstance(workers, bool) or not isinstance(workers, int) or not 1 <= workers <= 16:
            raise ValueError(f"render workers {workers!r} must be an int in [1, 16]")
        ctx = multiprocessing.get_context("spawn")
        self._on_result = on_result
        self._jobs: list[Any] = []
        self._results: list[Any] = []
        self._procs: list[Any] = []
        self._idle: deque[int] = deque()
        self._backlog: deque[Job] = deque()
        self._inflight: dict[int, int] = {}  # worker -> job id
        self._dead: set[int] = set()
        self._closed = False
        data = to_dict(scenario)
        for i in range(workers):
            job_r, job_w = ctx.Pipe(duplex=False)
            res_r, res_w = ctx.Pipe(duplex=False)
            p = ctx.Process(
                target=_worker, args=(i, data, renderer, encoding, job_r, res_w), daemon=True
            )
            p.start()
            job_r.close()
            res_w.close()
            self._jobs.append(job_w)
            self._results.append(res_r)
            self._procs.append(p)
        try:
            for i, conn in enumerate(self._results):
                if not conn.poll(start_timeout):
                    raise RuntimeError(f"render worker {i} did not start in {start_timeout:g} s")
                tag, detail = conn.recv()
                if tag != "ready":
                    raise RuntimeError(f"render worker {i} failed: {detail}")
                self._idle.append(i)
        except (RuntimeError, EOFError, OSError) as exc:
            self.close()
            raise RuntimeError(f"render pool: {exc}") from None
        self._reader = threading.Thread(target=self._read, name="render-results", daemon=True)
        self._reader.start()

    @property
    def workers(self) -> int:
        return len(self._procs)

    @property
    def alive(self) -> int:
        """Workers still running."""
        return len(self._procs) - len(self._dead)

    def submit(self, job: Job) -> None:
        """Queue a job (called by the owning loop only)."""
        if self._closed:
            raise RuntimeError("render pool is closed")
        self._backlog.append(job)
        self._dispatch()

    def worker_done(self, result: Result) -> None:
        """Free the worker of ``result`` again (the owning loop calls this for each one)."""
        self._inflight.pop(result.worker, None)
        if result.dead:
            self._dead.add(result.worker)
        else:
            self._idle.append(result.worker)
        self._dispatch()

    def take_backlog(self) -> list[Job]:
        """Jobs not yet sent (to render elsewhere when no worker is left)."""
        jobs = list(self._backlog)
        self._backlog.clear()
        return jobs

    def _dispatch(self) -> None:
        while self._idle and self._backlog:
            w = self._idle.popleft()
            job = self._backlog.popleft()
            self._inflight[w] = job.job_id
            try:
                self._jobs[w].send(job)
            except OSError:  # the worker is gone: its reader reports it
                self._backlog.appendleft(job)
                self._inflight.pop(w, None)

    def _read(self) -> None:
        conns = list(self._results)
        while conns and not self._closed:
            for ready in multiprocessing.connection.wait(conns, timeout=0.5):
                conn: Any = ready
                try:
                    res = conn.recv()
                except (EOFError, OSError):
                    conns.remove(conn)
                    w = self._results.index(conn)
                    if not self._closed:
                        job = self._inflight.get(w, -1)
                        self._on_result(Result(job, w, error="render worker died", dead=True))
                    continue
                if isinstance(res, Result):
                    self._on_result(res)

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        for conn in self._jobs:
            with contextlib.suppress(Exception):
                conn.send(None)
        for p in self._procs:
            p.join(timeout=5.0)
            if p.is_alive():
                p.terminate()
                p.join(timeout=5.0)
        for conn in (*self._jobs, *self._results):
            with contextlib.suppress(Exception):
                conn.close()
