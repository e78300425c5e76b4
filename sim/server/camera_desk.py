"""The world's camera service on its loop: a camera request becomes a look on the clock
(:mod:`sim.server.glances`), then a picture drawn in the world process or by the render
pool (:mod:`sim.server.render_pool`, at most one per robot in the works:
:mod:`sim.server.pending_pictures`) (docs/design.md §3, ``world/robot/{id}/camera``; docs/world.md "Clock").

Only the world loop of :mod:`sim.server.server` calls these methods: :meth:`CameraDesk.request`
for a checked camera request, :meth:`CameraDesk.capture_due` after every step of the
clock, :meth:`CameraDesk.rendered` for a render worker's result. With ``free_looks`` a
request is drawn at once and costs no time (the world before looks were charged).
"""

from __future__ import annotations

from collections.abc import Callable

from agent.wire import BUSY, CameraReply, ErrorReply, Message, picture, reason
from sim.camera import camera
from sim.camera.picture import Shot
from sim.physics.world import World
from sim.server.glances import Glances, LookTiming
from sim.server.pending_pictures import Admission, PendingPictures
from sim.server.render_pool import Job, RenderPool, Result
from sim.server.requests import Request

#: ``answer(query, message)``: a camera reply (held for its delay in a slow world).
Answer = Callable[[Request, Message], None]


class CameraDesk:
    """Camera requests of ``world``'s robots from request to reply (module docstring).

    ``answer`` sends a camera reply (the server's, delayed in a slow world), ``reply``
    an immediate one (superseded queries), ``log`` a line to the world's log. ``errors``
    counts the requests answered with an ``ErrorReply`` here; ``pool`` is the render
    pool, when the server opened one.
    """

    def __init__(
        self,
        world: World,
        answer: Answer,
        reply: Answer,
        log: Callable[[str], None],
        *,
        free_looks: bool = False,
        timing: LookTiming | None = None,
        encoding: str = picture.DEFAULT_ENCODING,
    ) -> None:
        self.world = world
        self._answer = answer
        self._reply = reply
        self._log = log
        self.pending: PendingPictures[Request] = PendingPictures(len(world.robot_ids))
        self.glances: Glances[Request] | None = None if free_looks else Glances(timing)
        self.pool: RenderPool | None = None
        self.errors = 0
        self._next_job = 0
        #: How replies carry pictures (:mod:`agent.wire.picture`); the pool's workers too.
        self.encoding = encoding

    @property
    def looking(self) -> bool:
        """True while a look is in flight (the clock must run for it)."""
        return self.glances is not None and len(self.glances) > 0

    def request(self, q: Request, rid: int, yaw: float) -> None:
        """A checked camera request of robot ``rid`` at head ``yaw``: a look starts (or a
        picture is drawn at once with free looks)."""
        if self.glances is None:
            self._shoot(q, rid, yaw, self.world.t_sim)
            return
        admission, superseded = self.glances.start(
            q, rid, yaw, self.world.head_yaw(rid), self.world.t_sim
        )
        if admission is Admission.BUSY:
            self.errors += 1
            self._answer(q, ErrorReply(reason=f"{BUSY}: robot {rid} is looking elsewhere"))
        elif superseded is not None:
            self._reply(superseded, ErrorReply(reason="superseded by a repeat"))

    def capture_due(self) -> None:
        """Take the pictures of the looks that have ended by now (the world's time)."""
        if self.glances is not None:
            now = self.world.t_sim
            for g in self.glances.due(now):
                self._shoot(g.query, g.robot_id, g.yaw, now)

    def _shoot(self, q: Request, rid: int, yaw: float, t_sim: float) -> None:
        try:
            rep = self._camera(q, rid, yaw, t_sim)
        except Exception as exc:  # never let one picture take the world loop down
            self.errors += 1
            self._log(f"camera robot {rid}: {reason(exc)}")
            why = (
                reason(exc, 480) if isinstance(exc, ValueError) else f"internal: {reason(exc, 470)}"
            )
            rep = ErrorReply(reason=why)
        if rep is not None:  # else a render worker has it
            self._answer(q, rep)

    def _camera(self, q: Request, rid: int, yaw: float, t_sim: float) -> Message | None:
        if self.pool is not None and self.pool.alive > 0:
            admission, superseded = self.pending.request(q, rid, yaw)
            if admission is Admission.BUSY:
                # drawn nothing: the robot may ask again later (agent.net.bus.Busy)
                self.errors += 1
                return ErrorReply(reason=f"{BUSY}: {len(self.pending)} pictures being drawn")
            if admission is Admission.REBOUND:  # its picture in the works answers this
                if superseded is not None:
                    self._reply(superseded, ErrorReply(reason="superseded by a repeat"))
                return None
            # The state the picture depends on is taken now; a worker draws it.
            shot = self.world.next_shot(rid, yaw)
            self.world.set_head_yaw(rid, yaw)
            heads = {r: self.world.head_yaw(r) for r in self.world.robot_ids}
            job = Job(self._next_job, rid, yaw, self.world.poses(), heads, shot)
            self._next_job += 1
            self.pending.add(job.job_id, q, rid, yaw, t_sim)
            self.pool.submit(job)
            return None
        return self._render_here(rid, yaw, t_sim)

    def _render_here(self, rid: int, yaw: float, t_sim: float, shot: Shot | None = None) -> Message:
        img = self.world.render(rid, yaw, shot)
        return CameraReply(
            robot_id=rid,
            yaw=self.world.head_yaw(rid),
            t_sim=t_sim,
            width=img.shape[1],
            height=img.shape[0],
            encoding=self.encoding,
            data=picture.picture_data(img, self.encoding),
        )

    def rendered(self, res: Result) -> None:
        """A worker's picture (or failure) for a pending camera request."""
        assert self.pool is not None
        self.pool.worker_done(res)
        pending = self.pending.done(res.job_id)
        if pending is not None:
            q, rid, yaw, t_sim = pending.query, pending.robot_id, pending.yaw, pending.t_sim
            if res.error:
                self.errors += 1
                self._log(f"camera robot {rid}: render failed: {reason(res.error)}")
                self._answer(q, ErrorReply(reason=f"render failed: {reason(res.error, 480)}"))
            else:
                msg = CameraReply(
                    robot_id=rid, yaw=yaw, t_sim=t_sim, width=camera.WIDTH,
                    height=camera.HEIGHT, encoding=self.encoding, data=res.data,
                )  # fmt: skip
                self._answer(q, msg)
        if res.dead:
            self._log(f"render worker {res.worker} died; {self.pool.alive} left")
            if self.pool.alive == 0:  # render what is left here, and from now on
                for job in self.pool.take_backlog():
                    left = self.pending.done(job.job_id)
                    if left is not None:
                        self._answer(
                            left.query,
                            self._render_here(job.robot_id, job.yaw, left.t_sim, job.shot),
                        )

    def close(self, why: str) -> None:
        """Answer every look and picture in the works with ``why``; close the pool."""
        waiting = [g.query for g in self.glances.drain()] if self.glances is not None else []
        waiting += [p.query for p in self.pending.drain()]
        for q in waiting:
            self._reply(q, ErrorReply(reason=why))
        if self.pool is not None:
            self.pool.close()
            self.pool = None
