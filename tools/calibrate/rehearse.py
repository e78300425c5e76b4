"""Rehearse: the whole calibration against virtual NAOs over qi (capture, build, check).

The simulated world (:class:`sim.physics.world.World`) with two robots is served in this process
by its world loop (:class:`sim.server.server.WorldServer`) and its qi gateway
(:class:`sim.naoqi_gateway.NaoqiGateway`): robot 1 is NAO-i, robot 2 NAO-j, each a
virtual NAO on its own qi port. The capture drives them exactly as it drives real NAOs
(:class:`agent.body.naoqi.NaoqiBody` over the qi protocol); only the person who places
NAO-j is played by :class:`WorldHand`, which puts it where the prompt says through the
world loop (:class:`RehearsalServer`, so the world is only ever touched by its loop). Turns on the spot carry the world's motion noise, as a real NAO's do: the
capture measures them with NAO-j's visual compass like on a real floor.

``look``: what the world looks like (a SPEC of :mod:`sim.camera.look`: the NAOs' orange, the
light, noise, motion blur, auto exposure); :func:`make_world` is the one place where a
look named on the command line becomes the world's. The world's clock charges every
picture the time a NAO takes for it (:mod:`sim.server.glances`), as a real NAO spends it.
"""

from __future__ import annotations

import contextlib
import math
import sys
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Future
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from agent.body.naoqi import NaoqiBody
from agent.core.perception.camera import CameraModel
from sim.camera.look import Look
from sim.naoqi_gateway import NaoqiGateway
from sim.physics.world import World
from sim.scenarios import RobotSpec, Scenario
from sim.server.server import NetConfig, WorldServer
from tools.calibrate.build import build
from tools.calibrate.capture import Placement, capture
from tools.calibrate.check import Floors, check, write
from tools.calibrate.folder import CaptureFolder
from tools.calibrate.plan import PlanSpec
from tools.harness.procs import free_port

OBSERVER, SUBJECT = 1, 2
NORTH = math.pi / 2


def make_world(look: str, seed: int = 0, noise: bool = True) -> World:
    """The world of a rehearsal: NAO-i at the origin facing north, NAO-j 1 m ahead, in a
    4 m room (NAO-j reaches 3.1 m ahead and to either side), in ``look`` (a SPEC of
    :mod:`sim.camera.look`; ``ValueError`` if it is not one)."""
    sc = Scenario(
        robots=(RobotSpec(OBSERVER, 0.0, 0.0, NORTH), RobotSpec(SUBJECT, 0.0, 1.0, -NORTH)),
        seed=seed,
        room=4.0,
        look=Look.parse(look),
    )
    return World(sc, noise=noise)


@dataclass(frozen=True)
class _Call:
    """A function for the world loop, queued with the requests (``kind`` names it there)."""

    fn: Callable[[World], Any]
    future: Future[Any]
    kind: str = "hand"


class RehearsalServer(WorldServer):
    """The world loop with a hand on the world: :meth:`call` runs a function in the loop,
    between requests, as the loop serves them (a rehearsal's person placing a robot)."""

    def call(self, fn: Callable[[World], Any]) -> Future[Any]:
        fut: Future[Any] = Future()
        self._queue("valid", _Call(fn, fut))
        return fut

    def _handle(self, lane: str, item: Any) -> None:
        if not isinstance(item, _Call):
            super()._handle(lane, item)
            return
        try:
            item.future.set_result(item.fn(self.world))
        except Exception as exc:
            item.future.set_exception(exc)
        self._publish_truth()


class WorldHand:
    """The person of a rehearsal: puts NAO-j where a placement says, facing NAO-i (in the
    world loop, between requests)."""

    def __init__(self, server: RehearsalServer, timeout: float = 30.0) -> None:
        self.server = server
        self.timeout = timeout
        self.placements = 0

    def __call__(self, p: Placement) -> None:
        def place(world: World) -> None:
            x0, y0, h0 = world.pose(p.observer)
            a = h0 + math.radians(p.bearing_deg)
            x, y = x0 + p.distance * math.cos(a), y0 + p.distance * math.sin(a)
            world.set_pose(p.subject, x, y, a + math.pi)

        self.server.call(place).result(self.timeout)
        self.placements += 1


@dataclass(frozen=True)
class Rehearsal:
    """Where a rehearsal left its folders, and how long its capture took."""

    captures: Path
    calibration: Path
    digest: str
    capture_wall_s: float
    failed: list[str]


@contextlib.contextmanager
def virtual_naos(world: World) -> Iterator[tuple[RehearsalServer, dict[int, str]]]:
    """The world loop in a thread and its qi gateway: ``(server, {id: url})``."""
    net = NetConfig(listen=(f"tcp/127.0.0.1:{free_port()}",), multicast_scouting=False)
    server = RehearsalServer(world, net)
    server.open()
    thread = threading.Thread(target=server.serve, name="world", daemon=True)
    thread.start()
    gateway = NaoqiGateway(server)
    try:
        yield server, gateway.open()
    finally:
        gateway.close()
        server.stop()
        thread.join(10.0)
        server.close()


def rehearse(
    look: str,
    out: Path,
    spec: PlanSpec,
    *,
    seed: int = 0,
    noise: bool = True,
    floors: Floors = Floors(),  # noqa: B008 (frozen)
    stream: TextIO | None = None,
) -> Rehearsal:
    """Capture into ``out/captures``, build ``out/calibration``, check it (report in
    ``out/calibration/report``)."""
    log = stream if stream is not None else sys.stderr
    out = Path(out)
    caps, cal_dir = out / "captures", out / "calibration"
    with make_world(look, seed, noise) as world, virtual_naos(world) as (server, urls):
        robots = {
            "observer": {"id": OBSERVER, "url": urls[OBSERVER]},
            "subject": {"id": SUBJECT, "url": urls[SUBJECT]},
        }
        extra = {"look": str(world.look), "rehearsal": {"seed": seed, "noise": noise}}
        folder = CaptureFolder.create_or_resume(caps, spec, robots, CameraModel(), extra)
        bodies: list[NaoqiBody] = []
        try:
            bodies.append(NaoqiBody(urls[OBSERVER], OBSERVER))
            bodies.append(NaoqiBody(urls[SUBJECT], SUBJECT))
            t0 = time.monotonic()
            capture(bodies[0], bodies[1], folder, WorldHand(server), stream=log)
            wall = time.monotonic() - t0
        finally:
            for b in bodies:
                b.close()
        print(f"capture: {len(folder.records)} views in {wall:.0f} s wall time", file=log)
    built = build(caps, cal_dir, stream=log)
    res = check(built.calibration, caps)
    failed = write(res, floors, cal_dir / "report")
    print(f"check: {res.summary()}", file=log)
    return Rehearsal(caps, cal_dir, built.digest, wall, failed)
