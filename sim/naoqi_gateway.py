"""Virtual NAOs: every simulated robot served as NAOqi services over the qi protocol (rehearsal for
a real NAO).

docs/design.md §8 "Bodies": a real NAO exposes its services at ``tcp://nao.local:9559``; here
each robot of the world gets one standalone qi session (its own service directory) on
its own port, with the services and methods an agent's NAOqi body uses, under their
NAOqi names and signatures:

- ``ALMotion``: ``wakeUp``, ``rest``, ``robotIsWakeUp``, ``moveInit``,
  ``moveTo(x, y, theta)`` (blocking; a forward/backward walk when ``y`` = ``theta`` = 0,
  a sidestep when ``x`` = ``theta`` = 0, a turn on the spot when ``x`` = ``y`` = 0;
  returns ``False`` when a contact stopped it, as NAOqi ≥ 2.5's ``moveTo`` reports an interrupted move), ``stopMove``,
  ``setAngles(names, angles, fractionMaxSpeed)`` and ``getAngles(names, useSensors)``
  for ``HeadYaw`` (clamped to ±119.5° like the real joint), ``getTime``.
- ``ALVideoDevice``: ``subscribeCamera(name, cameraIndex, resolution, colorSpace, fps)``
  for the top camera at kVGA in kBGRColorSpace only, ``getImageRemote(handle)`` (the
  NAOqi image array: width, height, layers, colour space, seconds, microseconds, the
  raw BGR bytes, camera index and the four angles of the field of view),
  ``releaseImage``, ``unsubscribe``.
- ``ALRobotPosture``: ``goToPosture(name, speed)``, ``getPosture``.

**Threads.** The world loop of :class:`sim.server.server.WorldServer` owns the world. A qi
method never touches it: it puts a request into the server's queue (the same queue its
zenoh queryables feed, with a query object that answers into a ``qi.Promise``) and
returns the promise's future at once, so qi's event loop never blocks on the world;
the loop renders or walks and completes the promise when it is done. Robot time
(image timestamps, ``getTime``) is sim time.
"""

from __future__ import annotations

import contextlib
import math
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import qi

from agent.wire import (
    CameraReply,
    CameraRequest,
    CommandReply,
    ErrorReply,
    Message,
    TurnRequest,
    WalkRequest,
    decode,
    encode,
    key_camera,
    key_turn,
    key_walk,
    nao,
    picture,
)
from sim.server.server import WorldServer

#: NAOqi image array: width, height, layers, colour space, s, µs, data, camera, 4 angles.
IMAGE_SIGNATURE = "(iiiiiiriffff)"
POSTURES = ("StandInit", "Stand", "StandZero", "Crouch", "Sit", "SitRelax", "LyingBelly")


class _Payload:
    def __init__(self, data: bytes) -> None:
        self._data = data

    def to_bytes(self) -> bytes:
        return self._data

    def __len__(self) -> int:
        return len(self._data)


class LocalQuery:
    """A request of a virtual NAO, shaped like the zenoh query the world loop serves
    (``key_expr``, ``payload``, ``parameters``, ``reply``, ``drop``)."""

    def __init__(self, key: str, msg: Message, on_reply: Callable[[Message], None]) -> None:
        self.key_expr = key
        self.payload = _Payload(encode(msg))
        self.parameters: dict[str, str] = {}
        self._on_reply = on_reply

    def reply(self, key: str, data: bytes) -> None:
        self._on_reply(decode(bytes(data)))

    def drop(self) -> None:
        """Nothing to release: a local query holds no network resources."""


@dataclass
class VirtualNao:
    """The NAOqi state of one simulated robot (what the world does not hold)."""

    robot_id: int
    server: WorldServer
    awake: bool = False
    posture: str = "Crouch"
    head_target: float = 0.0
    subscribers: set[str] = field(default_factory=set)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def ask(self, kind: str, key: str, msg: Message, done: Callable[[Message], Any]) -> Any:
        """Queue ``msg`` for the world loop; a qi future of ``done(reply)``."""
        promise = qi.Promise()

        def on_reply(rep: Message) -> None:
            try:
                if isinstance(rep, ErrorReply):
                    promise.setError(rep.reason)
                else:
                    promise.setValue(done(rep))
            except Exception as exc:  # the world loop must keep going
                promise.setError(f"{type(exc).__name__}: {exc}")

        self.server.admit_local(kind, LocalQuery(key, msg, on_reply))
        return promise.future()

    def need_awake(self, what: str) -> None:
        if not self.awake:
            raise RuntimeError(f"{what}: robot {self.robot_id} is not awake (call wakeUp)")


def _names(names: Any) -> list[str]:
    return [names] if isinstance(names, str) else [str(n) for n in names]


class ALMotion:
    def __init__(self, nao_: VirtualNao) -> None:
        self._nao = nao_

    def wakeUp(self) -> None:
        self._nao.awake = True

    def rest(self) -> None:
        self._nao.awake = False
        self._nao.posture = "Crouch"

    @qi.bind(qi.Bool, ())
    def robotIsWakeUp(self) -> bool:
        return self._nao.awake

    def moveInit(self) -> None:
        self._nao.need_awake("ALMotion.moveInit")

    @qi.bind(qi.Bool, (qi.Float, qi.Float, qi.Float))
    def moveTo(self, x: float, y: float, theta: float) -> Any:
        n = self._nao
        n.need_awake("ALMotion.moveTo")
        for v in (x, y, theta):
            if not math.isfinite(v):
                raise RuntimeError(f"ALMotion.moveTo: {v} is not finite")
        if sum(abs(v) > 1e-9 for v in (x, y, theta)) > 1:
            raise RuntimeError(
                "ALMotion.moveTo: the virtual NAO walks straight (y = 0, theta = 0), "
                "steps sideways (x = 0, theta = 0) or turns on the spot (x = y = 0)"
            )

        def ended(rep: Message) -> bool:
            assert isinstance(rep, CommandReply)
            return rep.status == "done"

        rid = n.robot_id
        if abs(theta) > 1e-9:
            return n.ask("turn", key_turn(rid), TurnRequest(angle=float(theta)), ended)
        if abs(y) > 1e-9:
            step = WalkRequest(distance=0.0, lateral=float(y))
            return n.ask("walk", key_walk(rid), step, ended)
        return n.ask("walk", key_walk(rid), WalkRequest(distance=float(x)), ended)

    def stopMove(self) -> None:
        """The simulated world finishes a motion itself: nothing to cut short."""

    @qi.bind(qi.Void, (qi.Dynamic, qi.Dynamic, qi.Float))
    def setAngles(self, names: Any, angles: Any, fractionMaxSpeed: float) -> None:
        names_ = _names(names)
        values = [float(angles)] if isinstance(angles, int | float) else [float(a) for a in angles]
        if len(values) != len(names_):
            raise RuntimeError(f"ALMotion.setAngles: {len(names_)} names, {len(values)} angles")
        if not 0.0 < fractionMaxSpeed <= 1.0:
            raise RuntimeError(f"ALMotion.setAngles: speed fraction {fractionMaxSpeed}")
        for name, v in zip(names_, values, strict=True):
            if name not in (nao.HEAD_YAW_JOINT, "Head"):
                raise RuntimeError(
                    f"ALMotion.setAngles: the virtual NAO moves HeadYaw only, not {name}"
                )
            if not math.isfinite(v):
                raise RuntimeError(f"ALMotion.setAngles: {v} is not finite")
            # the joint stops at its limits, as a real NAO's does
            lim = nao.HEAD_YAW_LIMIT
            self._nao.head_target = min(lim, max(-lim, v))

    @qi.bind(qi.List(qi.Float), (qi.Dynamic, qi.Bool))
    def getAngles(self, names: Any, useSensors: bool) -> list[float]:
        out = []
        for name in _names(names):
            if name not in (nao.HEAD_YAW_JOINT, "Head"):
                raise RuntimeError(
                    f"ALMotion.getAngles: the virtual NAO has HeadYaw only, not {name}"
                )
            out.append(self._nao.head_target)
        return out

    @qi.bind(qi.Float, (qi.Int32,))
    def getTime(self, timeOffset: int) -> float:
        return float(self._nao.server.world.t_sim) + timeOffset / 1000.0


class ALVideoDevice:
    def __init__(self, nao_: VirtualNao) -> None:
        self._nao = nao_
        self._count = 0

    @qi.bind(qi.String, (qi.String, qi.Int32, qi.Int32, qi.Int32, qi.Int32))
    def subscribeCamera(
        self, name: str, cameraIndex: int, resolution: int, colorSpace: int, fps: int
    ) -> str:
        if cameraIndex != nao.TOP_CAMERA:
            raise RuntimeError(
                f"ALVideoDevice: the virtual NAO has the top camera only (0), not {cameraIndex}"
            )
        if resolution != nao.RESOLUTION_VGA:
            raise RuntimeError(f"ALVideoDevice: resolution {resolution}: only kVGA (2)")
        if colorSpace != nao.COLORSPACE_BGR:
            raise RuntimeError(f"ALVideoDevice: colour space {colorSpace}: only kBGR (13)")
        with self._nao.lock:
            self._count += 1
            handle = f"{name}_{self._count}"
            self._nao.subscribers.add(handle)
        return handle

    @qi.bind(IMAGE_SIGNATURE, (qi.String,))
    def getImageRemote(self, handle: str) -> Any:
        n = self._nao
        if handle not in n.subscribers:
            raise RuntimeError(f"ALVideoDevice.getImageRemote: unknown handle {handle!r}")
        h2, v2 = nao.CAMERA_HFOV / 2, nao.CAMERA_VFOV / 2

        def image(rep: Message) -> list[Any]:
            assert isinstance(rep, CameraReply)
            img = picture.picture_of(rep.encoding, rep.width, rep.height, rep.data)
            sec = math.floor(rep.t_sim)
            usec = round((rep.t_sim - sec) * 1e6)
            h, w = img.shape[:2]
            return [w, h, 3, nao.COLORSPACE_BGR, sec, usec, img.tobytes(), nao.TOP_CAMERA,
                    h2, v2, -h2, -v2]  # fmt: skip

        rid = n.robot_id
        return n.ask("camera", key_camera(rid), CameraRequest(yaw=n.head_target), image)

    def releaseImage(self, handle: str) -> None:
        pass

    @qi.bind(qi.Bool, (qi.String,))
    def unsubscribe(self, handle: str) -> bool:
        with self._nao.lock:
            known = handle in self._nao.subscribers
            self._nao.subscribers.discard(handle)
        return known


class ALRobotPosture:
    def __init__(self, nao_: VirtualNao) -> None:
        self._nao = nao_

    @qi.bind(qi.Bool, (qi.String, qi.Float))
    def goToPosture(self, postureName: str, maxSpeedFraction: float) -> bool:
        if postureName not in POSTURES:
            raise RuntimeError(f"ALRobotPosture: unknown posture {postureName!r}")
        self._nao.awake = True  # a posture stiffens the joints, as on a NAO
        self._nao.posture = postureName
        return True

    @qi.bind(qi.String, ())
    def getPosture(self) -> str:
        return self._nao.posture


class NaoqiGateway:
    """One qi service directory per robot of ``server``'s world, on ``host``.

    ``base_port`` 0 takes a free port per robot; otherwise robot k (in id order) listens
    on ``base_port + k``. :meth:`open` returns {robot id: URL}.
    """

    def __init__(self, server: WorldServer, host: str = "127.0.0.1", base_port: int = 0) -> None:
        if not 0 <= base_port <= 65535 - len(server.world.robot_ids):
            raise ValueError(f"NAOqi base port {base_port} out of range")
        self.server = server
        self.host = host
        self.base_port = base_port
        self.sessions: dict[int, Any] = {}
        self.urls: dict[int, str] = {}
        self._keep: list[object] = []

    def open(self) -> dict[int, str]:
        qi.logging.setLevel(qi.logging.WARNING)  # one info line per service otherwise
        try:
            for k, rid in enumerate(self.server.world.robot_ids):
                port = self.base_port + k if self.base_port else 0
                s = qi.Session()
                s.listenStandalone(f"tcp://{self.host}:{port}")
                self.sessions[rid] = s
                v = VirtualNao(rid, self.server)
                for name, cls in (
                    ("ALMotion", ALMotion),
                    ("ALVideoDevice", ALVideoDevice),
                    ("ALRobotPosture", ALRobotPosture),
                ):
                    obj = cls(v)
                    self._keep.append(obj)
                    s.registerService(name, obj)
                self.urls[rid] = str(s.endpoints()[0])
        except Exception:
            self.close()
            raise
        return dict(self.urls)

    def close(self) -> None:
        for s in self.sessions.values():
            with contextlib.suppress(Exception):
                s.close()
        self.sessions.clear()
        self._keep.clear()
