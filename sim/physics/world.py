"""The simulated room and its robots (docs/design.md §4).

PyBullet in DIRECT mode (GUI opt-in) holds a square room whose floor and four walls are
each one textured quad with a rich, seeded texture (rectangles, discs, lines and
text-like marks in many colours) so that feature matching -- the visual compass of the
NAO paper 3.2.1 -- has plenty to hold on to; optional static obstacles (cylinders in the obstacle rose of :mod:`agent.core.nao`),
optional orange lookalike clutter and a light whose strength and direction vary for the
detector's hard cases. No wall or floor colour falls in (or near) the caps' colour nor in
the obstacle range: hues near the caps' (orange, and the hue a look turns them to) are
desaturated, and every texture is checked with ``cv2.inRange`` before use. That is the
NAO paper's premise (3.1.1): the caps and shoulders are the only things of their colour in
view, as a lab chooses its robots' colour against its room. The orange stays out of the
room in every look, so that the built-in calibration, made for orange caps, sees nothing
where the caps are of another colour.

Robots are kinematic NAO bodies (:mod:`sim.physics.nao_model`); their poses are held here
and moved by :mod:`sim.physics.locomotion`. The scenario's look (:mod:`sim.camera.look`)
recolours the NAOs' orange parts as the room is built and develops every picture
(:mod:`sim.camera.picture`). Rendering here costs no sim time (the server charges a look's
time, :mod:`sim.server.glances`).
:class:`World` is the in-process API; :mod:`sim.server.server` puts it on the bus.
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
import tempfile
from pathlib import Path
from types import TracebackType

import cv2
import numpy as np
import pybullet as pb

from agent.wire import nao
from sim.camera import camera, obj_mesh
from sim.camera import renderer as renderers
from sim.camera.picture import Shot, develop
from sim.physics.locomotion import Locomotion, NoiseModel, Obstacle
from sim.physics.nao_model import BOUNDING_RADIUS, HEAD_JOINT, ORANGE, NaoBodyFactory, link_colours
from sim.scenarios import Scenario

TEXELS_PER_M = 256
MAX_TEXTURE = 4096  # texels along a texture's longer side (memory and build time)
# The detector's orange (OpenCV HSV) widened by a margin: no room texel may fall in it.
GUARD_LO = (0, 110, 40)
GUARD_HI = (16, 255, 255)
OBSTACLE_HEIGHT = nao.OBSTACLE_HEIGHT
TILE = 1.0  # metres: edge of the triangles the floor and walls are cut into
#: Angle (rad) added to the camera's half field of view before a NAO counts as out of
#: view (the camera's 1.2° pitch tilts the image's side planes by less than this).
CULL_MARGIN = math.radians(5.0)


def _safe_colour(rng: np.random.Generator, turn: int = 0) -> tuple[int, int, int]:
    """A random BGR colour far from the orange and from the caps' colour (the orange turned
    by ``turn``, OpenCV hue units).

    Saturated colours take hues in OpenCV H [22, 160] counted from the orange's and from
    the caps' (yellow-green round to magenta for orange caps); the hues around either
    (reds, oranges and pinks for orange caps) are kept pale (S <= 90).
    """
    h = int(rng.integers(0, 180))
    v = int(rng.integers(30, 256))
    clear = 22 <= h <= 160 and 22 <= (h - turn) % 180 <= 160
    s = int(rng.integers(60, 256)) if clear else int(rng.integers(0, 91))
    hsv = np.array([[[h, s, v]]], dtype=np.uint8)
    b, g, r = cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)[0, 0]
    return int(b), int(g), int(r)


def make_texture(rng: np.random.Generator, width: int, height: int, turn: int = 0) -> np.ndarray:
    """A seeded BGR texture rich in corners and blobs, with no orange texel and none of the
    caps' colour (the orange turned by ``turn`` OpenCV hue units: a look's caps,
    :meth:`World.caps_turn`)."""
    base = np.array(_safe_colour(rng, turn), dtype=np.float64) * 0.4 + 110.0
    img = np.empty((height, width, 3), dtype=np.uint8)
    img[:] = np.clip(base, 0, 255).astype(np.uint8)
    area = width * height
    for _ in range(area // 2500):
        kind = int(rng.integers(0, 5))
        col = _safe_colour(rng, turn)
        x, y = int(rng.integers(0, width)), int(rng.integers(0, height))
        size = int(rng.integers(8, 90))
        if kind == 0:
            cv2.rectangle(img, (x, y), (x + size, y + int(rng.integers(8, 90))), col, -1)
        elif kind == 1:
            cv2.circle(img, (x, y), size // 2, col, -1)
        elif kind == 2:
            x2, y2 = x + int(rng.integers(-120, 120)), y + int(rng.integers(-120, 120))
            cv2.line(img, (x, y), (x2, y2), col, int(rng.integers(2, 8)))
        elif kind == 3:
            text = "".join(chr(int(c)) for c in rng.integers(65, 91, size=int(rng.integers(2, 7))))
            cv2.putText(img, text, (x, y), cv2.FONT_HERSHEY_SIMPLEX, size / 40.0, col, 2)
        else:
            pts = rng.integers(-size, size, size=(int(rng.integers(3, 6)), 2)) + np.array([x, y])
            cv2.fillPoly(img, [pts.astype(np.int32)], col)
    # Belt and braces: desaturate anything that still lands near the orange or the caps'.
    hsv = cv2.cvtColor(img, cv2.COLOR_BGR2HSV)
    bad = _near_orange(hsv)
    if turn:  # hues counted from the caps'
        rel = hsv.copy()
        rel[..., 0] = (hsv[..., 0].astype(np.int16) - turn) % 180
        bad |= _near_orange(rel)
    bad |= cv2.inRange(hsv, nao.OBSTACLE_HSV_LO, nao.OBSTACLE_HSV_HI) > 0
    if bad.any():
        grey = img[bad].mean(axis=1, keepdims=True)
        img[bad] = np.clip(grey, 0, 255).astype(np.uint8)
    return img


def _near_orange(hsv: np.ndarray) -> np.ndarray:
    """The texels of an HSV image in the guard band around the orange."""
    bad: np.ndarray = cv2.inRange(hsv, GUARD_LO, GUARD_HI) > 0
    bad |= cv2.inRange(hsv, (170, 110, 40), (180, 255, 255)) > 0
    return bad


def light_direction(azimuth: float, elevation: float) -> tuple[float, float, float]:
    return (
        math.cos(elevation) * math.cos(azimuth),
        math.cos(elevation) * math.sin(azimuth),
        math.sin(elevation),
    )


class World:
    """A room with NAOs; poses, head yaws, the sim clock, and their forehead cameras.

    ``noise`` switches the seeded motion noise of :mod:`sim.physics.locomotion` on or off;
    ``noise_scale`` multiplies it (:meth:`~sim.physics.locomotion.NoiseModel.scaled`);
    ``world.locomotion`` runs walk/turn commands (``walk``, ``turn``, ``step``).
    ``renderer`` (:mod:`sim.camera.renderer`): ``tiny`` (default), ``egl`` or ``auto``;
    ``world.renderer`` is the one used and ``world.renderer_why`` why. The look is the
    scenario's (``world.look``).
    """

    def __init__(
        self,
        scenario: Scenario,
        *,
        gui: bool = False,
        noise: bool = True,
        noise_scale: float = 1.0,
        renderer: str = "tiny",
        egl_plugin: str | None = None,
    ) -> None:
        self.scenario = scenario
        self.look = scenario.look
        orange = self.look.recolour(ORANGE)
        self._orange = orange
        self._link_colours = link_colours(orange)
        if gui:  # the GUI is an OpenGL window of its own; its pictures are TinyRenderer's
            if renderers.check(renderer) == "egl":
                raise ValueError("--gui draws the cameras with TinyRenderer, not --renderer egl")
            choice = renderers.Choice("tiny", "the GUI draws the cameras with TinyRenderer")
        else:
            choice = renderers.choose(renderer, egl_plugin)
        self.renderer = choice.name
        self.renderer_why = choice.why
        self.noise = noise
        self.noise_model = NoiseModel().scaled(noise_scale) if noise else NoiseModel.none()
        if gui and sys.platform.startswith("linux") and not os.environ.get("DISPLAY"):
            # PyBullet's GUI would end the whole process on a missing X server.
            raise ValueError("the GUI needs a display, and DISPLAY is not set")
        self._client = int(pb.connect(pb.GUI if gui else pb.DIRECT))
        if self._client < 0:
            raise RuntimeError("cannot connect to PyBullet")
        self._closed = False
        try:
            if self.renderer == "egl":
                renderers.load_egl(self._client, egl_plugin)
            self._build()
        except Exception:
            self.close()
            raise

    # ------------------------------------------------------------------ building

    def _build(self) -> None:
        sc = self.scenario
        cid = self._client
        pb.resetSimulation(physicsClientId=cid)
        if pb.getConnectionInfo(cid).get("connectionMethod") == pb.GUI:
            pb.configureDebugVisualizer(pb.COV_ENABLE_GUI, 0, physicsClientId=cid)
        li = sc.light
        self._light_dir = light_direction(li.azimuth, li.elevation)
        self._light_intensity = li.intensity
        with tempfile.TemporaryDirectory(prefix="nao-sim-") as tmp:
            self._build_in(Path(tmp))
        if self.renderer == "egl":
            with renderers.quiet_stdout():  # the plugin prints on its first pictures
                for _ in range(2):
                    self._draw(0.0, 0.0, 0.0, 0.0)
        self.robot_ids: tuple[int, ...] = tuple(sorted(self._bodies))
        self.locomotion = Locomotion(
            self,
            seed=sc.seed,
            noise=self.noise_model,
            obstacles=tuple(Obstacle(o.x, o.y, o.radius) for o in sc.obstacles),
            room=sc.room,
        )

    def _egl_part_shade(self) -> float:
        """The colour factor of the EGL renderer's NAOs, obstacles and clutter: TinyRenderer's
        light over the plugin's, averaged over horizontal normals (the sides the cameras
        see)."""
        normals = [(math.cos(a), math.sin(a), 0.0) for a in np.linspace(0, 2 * math.pi, 36, False)]
        return float(
            np.mean(
                [
                    renderers.tiny_shade(n, self._light_dir, self._light_intensity)
                    / renderers.egl_shade(n, self._light_dir)
                    for n in normals
                ]
            )
        )

    @property
    def caps_turn(self) -> int:
        """How far the look turns the caps' hue, in OpenCV hue units (0 for orange caps): the
        room's textures keep clear of the caps' colour (module docstring)."""
        return round(self.look.hue / 2.0) % 180

    def _build_in(self, tmp: Path) -> None:
        """Build the room (files for textures and, with EGL, meshes go to ``tmp``)."""
        sc = self.scenario
        cid = self._client
        egl = self.renderer == "egl"
        shade = self._egl_part_shade() if egl else 1.0
        # Near things first: TinyRenderer then skips shading wall texels hidden by them.
        factory = NaoBodyFactory(cid, tmp if egl else None, shade, self._orange)
        self._bodies: dict[int, int] = {}
        self._poses: dict[int, tuple[float, float, float]] = {}
        self._head: dict[int, float] = {}
        self._frames: dict[int, int] = {}  # pictures taken, per robot
        self._shot_yaw: dict[int, float] = {}  # head yaw of each robot's last picture
        self._dirty: set[int] = set()
        self._hidden: set[int] = set()  # robots made transparent: out of the last view
        for r in sorted(sc.robots, key=lambda r: r.id):
            self._bodies[r.id] = factory.create(r.x, r.y, r.heading)
            self._poses[r.id] = (float(r.x), float(r.y), _wrap(float(r.heading)))
            self._head[r.id] = 0.0
            self._frames[r.id] = 0
            self._shot_yaw[r.id] = 0.0
        rng = np.random.default_rng([sc.seed, 0x5EED])
        turn = self.caps_turn
        half = sc.room
        wall_h = 0.8 + 1.2 * half  # the top of the view from a far corner stays on the wall
        # Floor: z = 0, seen from above.
        self._quad(
            tmp / "floor.png",
            [(-half, -half, 0.0), (half, -half, 0.0), (half, half, 0.0), (-half, half, 0.0)],
            (0.0, 0.0, 1.0),
            make_texture(rng, *_texture_size(2 * half, 2 * half, 160), turn),
        )
        corners = [(-half, -half), (half, -half), (half, half), (-half, half)]
        for i in range(4):
            (x0, y0), (x1, y1) = corners[i], corners[(i + 1) % 4]
            # Inward normal: rotate the wall direction by +90° (counter-clockwise room).
            dx, dy = (x1 - x0) / (2 * half), (y1 - y0) / (2 * half)
            tex = make_texture(rng, *_texture_size(2 * half, wall_h, TEXELS_PER_M), turn)
            self._quad(
                tmp / f"wall{i}.png",
                [(x0, y0, 0.0), (x1, y1, 0.0), (x1, y1, wall_h), (x0, y0, wall_h)],
                (-dy, dx, 0.0),
                tex,
                flip=True,  # wound to face into the room
            )
        for ob in sc.obstacles:
            vis = pb.createVisualShape(
                pb.GEOM_CYLINDER,
                radius=ob.radius,
                length=OBSTACLE_HEIGHT,
                rgbaColor=_scaled(nao.OBSTACLE_RGBA, shade),
                specularColor=(0.0, 0.0, 0.0),
                physicsClientId=cid,
            )
            pb.createMultiBody(
                baseVisualShapeIndex=vis,
                basePosition=(ob.x, ob.y, OBSTACLE_HEIGHT / 2),
                physicsClientId=cid,
            )
        for k, cl in enumerate(sc.clutter):
            if egl:  # the plugin shades a GEOM_BOX smooth; TinyRenderer has flat faces
                mesh = obj_mesh.write(tmp / f"clutter{k}.obj", *obj_mesh.box((cl.size / 2,) * 3))
                vis = pb.createVisualShape(
                    pb.GEOM_MESH,
                    fileName=str(mesh),
                    rgbaColor=_scaled((1.0, 0.25, 0.0, 1.0), shade),
                    physicsClientId=cid,
                )
            else:
                vis = pb.createVisualShape(
                    pb.GEOM_BOX,
                    halfExtents=(cl.size / 2,) * 3,
                    rgbaColor=(1.0, 0.25, 0.0, 1.0),
                    specularColor=(0.0, 0.0, 0.0),
                    physicsClientId=cid,
                )
            pb.createMultiBody(
                baseVisualShapeIndex=vis, basePosition=(cl.x, cl.y, cl.z), physicsClientId=cid
            )

    @property
    def t_sim(self) -> float:
        """Sim time (s): advanced only by :meth:`Locomotion.step` (walks, turns and the
        server's looks, :mod:`sim.server.glances`); rendering here costs none."""
        return self.locomotion.t_sim

    def _quad(
        self,
        path: Path,
        verts: list[tuple[float, float, float]],
        normal: tuple[float, float, float],
        texture: np.ndarray,
        flip: bool = False,
    ) -> None:
        """One textured quad (corners ``verts`` counter-clockwise as seen from the side
        it faces; ``flip`` reverses that), cut into tiles of about TILE metres.

        TinyRenderer walks the screen bounding box of every triangle, so a few huge
        triangles cost a full-screen pass each; small tiles keep a render fast.
        """
        cid = self._client
        cv2.imwrite(str(path), texture)
        tex_id = pb.loadTexture(str(path), physicsClientId=cid) if self.renderer == "tiny" else -1
        p0, p1, _, p3 = (np.array(v, dtype=np.float64) for v in verts)
        eu, ev = p1 - p0, p3 - p0
        nu = max(1, math.ceil(float(np.linalg.norm(eu)) / TILE))
        nv = max(1, math.ceil(float(np.linalg.norm(ev)) / TILE))
        vs: list[list[float]] = []
        uvs: list[tuple[float, float]] = []
        for j in range(nv + 1):
            for i in range(nu + 1):
                a, b = i / nu, j / nv
                vs.append((p0 + a * eu + b * ev).tolist())
                uvs.append((1.0 - a if flip else a, b))  # text reads left to right
        idx: list[int] = []
        for j in range(nv):
            for i in range(nu):
                k = j * (nu + 1) + i
                q = (k, k + 1, k + nu + 2, k, k + nu + 2, k + nu + 1)
                idx.extend((q[0], q[2], q[1], q[3], q[5], q[4]) if flip else q)
        if self.renderer == "egl":
            # The plugin takes the texture from the OBJ's material, and its light from
            # the colour: TinyRenderer's light on this flat quad over the plugin's.
            f = renderers.tiny_shade(
                normal, self._light_dir, self._light_intensity
            ) / renderers.egl_shade(normal, self._light_dir)
            normals = [list(normal)] * len(vs)
            mesh = obj_mesh.write(path.with_suffix(".obj"), vs, normals, idx, uvs, path)
            vis = pb.createVisualShape(
                pb.GEOM_MESH, fileName=str(mesh), rgbaColor=(f, f, f, 1.0), physicsClientId=cid
            )
            pb.createMultiBody(baseVisualShapeIndex=vis, physicsClientId=cid)
            return
        vis = pb.createVisualShape(
            pb.GEOM_MESH,
            vertices=vs,
            indices=idx,
            uvs=uvs,
            normals=[normal] * len(vs),
            rgbaColor=(1.0, 1.0, 1.0, 1.0),
            specularColor=(0.0, 0.0, 0.0),
            physicsClientId=cid,
        )
        body = pb.createMultiBody(baseVisualShapeIndex=vis, physicsClientId=cid)
        pb.changeVisualShape(body, -1, textureUniqueId=tex_id, physicsClientId=cid)

    # ------------------------------------------------------------------ state

    def _check(self, robot_id: int) -> int:
        if robot_id not in self._bodies:
            raise ValueError(f"unknown robot {robot_id!r}; robots are {list(self.robot_ids)}")
        return robot_id

    def pose(self, robot_id: int) -> tuple[float, float, float]:
        """Ground-truth (x, y, heading) of a robot; heading wrapped to [-pi, pi)."""
        return self._poses[self._check(robot_id)]

    def poses(self) -> dict[int, tuple[float, float, float]]:
        return dict(self._poses)

    def head_yaw(self, robot_id: int) -> float:
        return self._head[self._check(robot_id)]

    def set_pose(self, robot_id: int, x: float, y: float, heading: float) -> None:
        """Teleport a robot (tools and tests; locomotion moves robots through it too).

        The PyBullet body follows lazily, at the next render: stepping many robots costs
        no renderer calls.
        """
        self._check(robot_id)
        for v in (x, y, heading):
            if not math.isfinite(v):
                raise ValueError(f"pose value {v} is not finite")
        self._poses[robot_id] = (float(x), float(y), _wrap(float(heading)))
        self._dirty.add(robot_id)

    def _sync(self) -> None:
        for rid in sorted(self._dirty):
            x, y, th = self._poses[rid]
            pb.resetBasePositionAndOrientation(
                self._bodies[rid],
                (x, y, 0.0),
                pb.getQuaternionFromEuler((0.0, 0.0, th)),
                physicsClientId=self._client,
            )
        self._dirty.clear()

    def set_head_yaw(self, robot_id: int, yaw: float) -> None:
        """Turn a robot's head (±119.5°; outside is a ``ValueError``)."""
        self._check(robot_id)
        y = camera.check_yaw(yaw)
        self._head[robot_id] = y
        pb.resetJointState(self._bodies[robot_id], HEAD_JOINT, y, physicsClientId=self._client)

    def next_shot(self, robot_id: int, head_yaw: float) -> Shot:
        """Number robot ``robot_id``'s next picture, taken at ``head_yaw``: its frame
        number and how far its head turned since its last picture (:mod:`sim.camera.picture`)."""
        self._check(robot_id)
        y = camera.check_yaw(head_yaw)
        shot = Shot(robot_id, self._frames[robot_id], y - self._shot_yaw[robot_id])
        self._frames[robot_id] += 1
        self._shot_yaw[robot_id] = y
        return shot

    def render(self, robot_id: int, head_yaw: float, shot: Shot | None = None) -> np.ndarray:
        """What ``robot_id``'s forehead camera sees with its head at ``head_yaw`` (rad),
        developed in the world's look as picture ``shot`` (default: :meth:`next_shot`).

        The robot's head stays at that yaw afterwards (others see it turned). The
        observer's own body is not drawn. Returns (480, 640, 3) uint8 BGR.
        """
        self._check(robot_id)
        if shot is None:
            shot = self.next_shot(robot_id, head_yaw)
        img = self._render(robot_id, head_yaw)
        return develop(img, self.look, shot, self.scenario.seed)

    def _render(self, robot_id: int, head_yaw: float) -> np.ndarray:
        """The renderer's picture of :meth:`render` (before the look develops it)."""
        self.set_head_yaw(robot_id, head_yaw)
        self._sync()
        x, y, th = self._poses[robot_id]
        body = self._bodies[robot_id]
        cid = self._client
        if self.renderer == "tiny":  # OpenGL clips what is out of view by itself
            self._cull(robot_id)
        # Hide the observer's own body (under the floor) while its camera renders.
        pb.resetBasePositionAndOrientation(body, (x, y, -5.0), (0, 0, 0, 1), physicsClientId=cid)
        try:
            return self._draw(x, y, th, self._head[robot_id])
        finally:
            pb.resetBasePositionAndOrientation(
                body, (x, y, 0.0), pb.getQuaternionFromEuler((0.0, 0.0, th)), physicsClientId=cid
            )

    def _draw(self, x: float, y: float, heading: float, yaw: float) -> np.ndarray:
        return camera.render(
            self._client,
            x,
            y,
            heading,
            yaw,
            light_direction=self._light_dir,
            light_intensity=self._light_intensity,
            renderer=pb.ER_BULLET_HARDWARE_OPENGL
            if self.renderer == "egl"
            else pb.ER_TINY_RENDERER,
        )

    def _cull(self, robot_id: int) -> None:
        """Make the NAOs out of ``robot_id``'s view transparent, and those in view opaque
        again. TinyRenderer skips a transparent shape but draws every other triangle,
        seen or not (at 50 NAOs 95 ms a picture, 79 ms culled); a NAO whose bounding
        cylinder lies wholly outside the horizontal field of view (plus
        :data:`CULL_MARGIN`) draws no pixel, so the picture is the same
        (``tests/sim/camera/test_render.py`` compares them)."""
        x, y, th = self._poses[robot_id]
        eye, _, _ = camera.camera_pose(x, y, th, self._head[robot_id])
        look = th + self._head[robot_id]
        half = camera.HFOV / 2.0 + CULL_MARGIN
        cid = self._client
        for rid, (rx, ry, _) in self._poses.items():
            if rid == robot_id:
                continue
            dx, dy = rx - float(eye[0]), ry - float(eye[1])
            d = math.hypot(dx, dy)
            off = abs(_wrap(math.atan2(dy, dx) - look))
            seen = d <= 2.0 * BOUNDING_RADIUS or off <= half + math.asin(BOUNDING_RADIUS / d)
            if seen == (rid in self._hidden):
                body = self._bodies[rid]
                for link, rgba in enumerate(self._link_colours):
                    colour = rgba if seen else (rgba[0], rgba[1], rgba[2], 0.0)
                    pb.changeVisualShape(body, link, rgbaColor=colour, physicsClientId=cid)
                if seen:
                    self._hidden.discard(rid)
                else:
                    self._hidden.add(rid)

    # ------------------------------------------------------------------ lifetime

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            with renderers.quiet_stdout() if self.renderer == "egl" else contextlib.nullcontext():
                pb.disconnect(physicsClientId=self._client)

    def __enter__(self) -> World:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def _texture_size(width_m: float, height_m: float, per_m: int) -> tuple[int, int]:
    """Texture size for a quad, at ``per_m`` texels per metre but at most MAX_TEXTURE."""
    scale = min(float(per_m), MAX_TEXTURE / max(width_m, height_m))
    return max(16, int(width_m * scale)), max(16, int(height_m * scale))


def _scaled(rgba: tuple[float, float, float, float], k: float) -> tuple[float, ...]:
    """``rgba`` with its colour (not its alpha) times ``k`` (unchanged for k = 1)."""
    if k == 1.0:
        return tuple(rgba)
    return (rgba[0] * k, rgba[1] * k, rgba[2] * k, rgba[3])


def _wrap(a: float) -> float:
    """Angle wrapped to [-pi, pi)."""
    return (a + math.pi) % (2 * math.pi) - math.pi
