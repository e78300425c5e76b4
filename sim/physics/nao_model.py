"""A NAO-like body built from primitives (docs/design.md §4; NAO paper §3.1, Fig. 3).

Sized to the NAO H25: 0.573 m tall, 0.275-0.28 m wide (shoulder to shoulder covers),
about 0.16 m deep at the feet (the paper's 0.311 m depth includes the arms held forward;
standing "StandZero" with arms down, the body is shallower). White/grey body; the orange
parts the detector uses are the **head cap** (a band round the top of the head plus the
back of the head) and the two **shoulder covers**. A front or back view therefore shows
3 orange blobs, a side view 2 (the far shoulder hides behind the near one and the torso),
and the look changes with the orientation as in Fig. 3: the head blob is a thin band from
the front and a tall patch from the back, the shoulders slide together and overlap as the
robot turns.

Body frame: x forward, y left, z up, origin on the floor between the feet. The head is a
link on a revolute joint about z (the head yaw), so a robot that looks sideways is seen
with its head turned (Fig. 3(e)). Colours are chosen so that only the orange parts fall
in the detector's HSV range (H 2-10, S >= 170, V >= 50, OpenCV scale) under the default
light; every other colour of the model is white, grey or near-black.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import pybullet as pb

from sim.camera import obj_mesh

HEIGHT = 0.573
WIDTH = 0.28
NECK_Z = 0.455  # head yaw joint height
CAMERA_Z = 0.50  # forehead camera height above the floor
CAMERA_FORWARD = 0.062  # forehead camera in front of the head yaw axis
FOOTPRINT_RADIUS = 0.155  # contact radius of the body (half the 0.311 m depth)

ORANGE = (1.0, 0.22, 0.0, 1.0)  # HSV hue 13° -> OpenCV H 6.5, S 255
WHITE = (0.93, 0.93, 0.94, 1.0)
GREY = (0.55, 0.56, 0.6, 1.0)
DARK = (0.12, 0.12, 0.14, 1.0)


@dataclass(frozen=True)
class Part:
    """A primitive at ``pos`` in the body (or head) frame, colour ``rgba``.

    ``shape`` is ``box`` (``size`` = half extents), ``cyl`` (``size`` = (radius, radius,
    half length), axis z before ``rpy``) or ``sphere`` (``size`` = (r, r, r)).
    """

    name: str
    shape: str
    size: tuple[float, float, float]
    pos: tuple[float, float, float]
    rgba: tuple[float, float, float, float]
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)


EYE = (0.45, 0.7, 1.0, 1.0)
ALONG_X = (0.0, math.pi / 2, 0.0)  # a cylinder's axis turned from z to x
ALONG_Y = (math.pi / 2, 0.0, 0.0)

# Fixed to the torso (body frame).
BODY_PARTS: tuple[Part, ...] = (
    Part("foot_l", "box", (0.080, 0.045, 0.015), (0.020, 0.055, 0.015), GREY),
    Part("foot_r", "box", (0.080, 0.045, 0.015), (0.020, -0.055, 0.015), GREY),
    Part("shin_l", "cyl", (0.034, 0.034, 0.070), (0.000, 0.055, 0.100), WHITE),
    Part("shin_r", "cyl", (0.034, 0.034, 0.070), (0.000, -0.055, 0.100), WHITE),
    Part("knee_l", "sphere", (0.036, 0.036, 0.036), (0.004, 0.055, 0.172), GREY),
    Part("knee_r", "sphere", (0.036, 0.036, 0.036), (0.004, -0.055, 0.172), GREY),
    Part("thigh_l", "cyl", (0.040, 0.040, 0.055), (0.000, 0.055, 0.230), WHITE),
    Part("thigh_r", "cyl", (0.040, 0.040, 0.055), (0.000, -0.055, 0.230), WHITE),
    Part("pelvis", "box", (0.050, 0.085, 0.025), (0.000, 0.000, 0.295), GREY),
    Part("torso", "box", (0.055, 0.075, 0.075), (0.000, 0.000, 0.385), WHITE),
    Part("chest", "cyl", (0.026, 0.026, 0.003), (0.056, 0.000, 0.405), GREY, ALONG_X),
    Part("neck", "cyl", (0.020, 0.020, 0.012), (0.000, 0.000, 0.462), GREY),
    Part("shoulder_l", "sphere", (0.038, 0.038, 0.038), (0.000, 0.100, 0.430), ORANGE),
    Part("shoulder_r", "sphere", (0.038, 0.038, 0.038), (0.000, -0.100, 0.430), ORANGE),
    Part("arm_l", "cyl", (0.028, 0.028, 0.050), (0.000, 0.100, 0.345), WHITE),
    Part("arm_r", "cyl", (0.028, 0.028, 0.050), (0.000, -0.100, 0.345), WHITE),
    Part("hand_l", "cyl", (0.025, 0.025, 0.050), (0.010, 0.100, 0.250), GREY),
    Part("hand_r", "cyl", (0.025, 0.025, 0.050), (0.010, -0.100, 0.250), GREY),
)

# On the head link (head frame: origin on the yaw axis at NECK_Z).
HEAD_PARTS: tuple[Part, ...] = (
    Part("head", "cyl", (0.060, 0.060, 0.053), (0.000, 0.000, 0.060), WHITE),
    Part("face", "box", (0.004, 0.036, 0.024), (0.052, 0.000, 0.052), DARK),
    Part("eye_l", "cyl", (0.011, 0.011, 0.003), (0.057, 0.020, 0.056), EYE, ALONG_X),
    Part("eye_r", "cyl", (0.011, 0.011, 0.003), (0.057, -0.020, 0.056), EYE, ALONG_X),
    Part("ear_l", "cyl", (0.026, 0.026, 0.006), (0.000, 0.061, 0.055), GREY, ALONG_Y),
    Part("ear_r", "cyl", (0.026, 0.026, 0.006), (0.000, -0.061, 0.055), GREY, ALONG_Y),
    Part("cap", "cyl", (0.063, 0.063, 0.014), (0.000, 0.000, 0.104), ORANGE),
    Part("cap_back", "box", (0.008, 0.045, 0.030), (-0.056, 0.000, 0.072), ORANGE),
)


Mesh = tuple[list[list[float]], list[list[float]], list[int]]


def cylinder_mesh(r: float, half: float, segments: int = 14) -> Mesh:
    """A closed cylinder about z (vertices, smooth side normals, CCW-outward triangles)."""
    verts: list[list[float]] = []
    normals: list[list[float]] = []
    idx: list[int] = []
    for i in range(segments):
        a = 2 * math.pi * i / segments
        c, s = math.cos(a), math.sin(a)
        verts += [[r * c, r * s, -half], [r * c, r * s, half]]
        normals += [[c, s, 0.0], [c, s, 0.0]]
    for i in range(segments):
        b0, t0 = 2 * i, 2 * i + 1
        b1, t1 = (2 * i + 2) % (2 * segments), (2 * i + 3) % (2 * segments)
        idx += [b0, b1, t1, b0, t1, t0]
    for z, nz in ((half, 1.0), (-half, -1.0)):
        centre = len(verts)
        verts.append([0.0, 0.0, z])
        normals.append([0.0, 0.0, nz])
        ring = len(verts)
        for i in range(segments):
            a = 2 * math.pi * i / segments
            verts.append([r * math.cos(a), r * math.sin(a), z])
            normals.append([0.0, 0.0, nz])
        for i in range(segments):
            j = (i + 1) % segments
            idx += [centre, ring + i, ring + j] if nz > 0 else [centre, ring + j, ring + i]
    return verts, normals, idx


def sphere_mesh(r: float, rings: int = 8, segments: int = 14) -> Mesh:
    """A UV sphere (vertices, smooth normals, CCW-outward triangles)."""
    verts: list[list[float]] = []
    normals: list[list[float]] = []
    idx: list[int] = []
    for j in range(rings + 1):
        lat = -math.pi / 2 + math.pi * j / rings
        for i in range(segments + 1):
            lon = 2 * math.pi * i / segments
            n = [math.cos(lat) * math.cos(lon), math.cos(lat) * math.sin(lon), math.sin(lat)]
            normals.append(n)
            verts.append([r * v for v in n])
    w = segments + 1
    for j in range(rings):
        for i in range(segments):
            b0, b1, t0, t1 = j * w + i, j * w + i + 1, (j + 1) * w + i, (j + 1) * w + i + 1
            idx += [b0, b1, t1, b0, t1, t0]
    return verts, normals, idx


class NaoBodyFactory:
    """Creates NAO multibodies in one PyBullet client, sharing the visual shapes.

    With ``mesh_dir`` (the EGL renderer, :mod:`sim.camera.renderer`) every part is an OBJ file
    written there (the same vertices and normals; boxes with flat faces) and its colour is
    multiplied by ``shade`` (the light factor that matches TinyRenderer's light).
    ``orange``: the colour of the orange parts (a look recolours them, :mod:`sim.camera.look`).
    """

    def __init__(
        self,
        client: int,
        mesh_dir: Path | None = None,
        shade: float = 1.0,
        orange: tuple[float, float, float, float] = ORANGE,
    ) -> None:
        self._client = client
        self._mesh_dir = mesh_dir
        self._shade = shade
        self._orange = orange
        self._body_shapes = [self._shape(p, (0.0, 0.0, 0.0)) for p in BODY_PARTS]
        # The head's root shape sits at its offset on the head link itself.
        self._head_root = self._shape(HEAD_PARTS[0], HEAD_PARTS[0].pos)
        self._head_shapes = [self._shape(p, (0.0, 0.0, 0.0)) for p in HEAD_PARTS[1:]]

    def _colour(self, part: Part) -> tuple[float, float, float, float]:
        return self._orange if part.rgba == ORANGE else part.rgba

    def _shape(self, part: Part, offset: tuple[float, float, float]) -> int:
        if self._mesh_dir is not None:
            return self._obj_shape(part, offset, self._mesh_dir)
        common: dict[str, object] = {
            "rgbaColor": self._colour(part),
            "specularColor": (0.0, 0.0, 0.0),
            "visualFramePosition": offset,
            "visualFrameOrientation": pb.getQuaternionFromEuler(part.rpy),
            "physicsClientId": self._client,
        }
        if part.shape == "box":
            vid = pb.createVisualShape(pb.GEOM_BOX, halfExtents=part.size, **common)
        elif part.shape in ("cyl", "sphere"):
            # Low-poly meshes: TinyRenderer pays per triangle of every body, visible or not.
            if part.shape == "cyl":
                verts, normals, idx = cylinder_mesh(part.size[0], part.size[2])
            else:
                verts, normals, idx = sphere_mesh(part.size[0])
            vid = pb.createVisualShape(
                pb.GEOM_MESH, vertices=verts, normals=normals, indices=idx, **common
            )
        else:
            raise ValueError(f"unknown part shape {part.shape!r}")
        return int(vid)

    def _obj_shape(self, part: Part, offset: tuple[float, float, float], where: Path) -> int:
        if part.shape == "box":
            verts, normals, idx = obj_mesh.box(part.size)
        elif part.shape == "cyl":
            verts, normals, idx = cylinder_mesh(part.size[0], part.size[2])
        elif part.shape == "sphere":
            verts, normals, idx = sphere_mesh(part.size[0])
        else:
            raise ValueError(f"unknown part shape {part.shape!r}")
        path = obj_mesh.write(where / f"nao_{part.name}.obj", verts, normals, idx)
        k = self._shade
        c = self._colour(part)
        vid = pb.createVisualShape(
            pb.GEOM_MESH,
            fileName=str(path),
            rgbaColor=(c[0] * k, c[1] * k, c[2] * k, c[3]),
            specularColor=(0.0, 0.0, 0.0),
            visualFramePosition=offset,
            visualFrameOrientation=pb.getQuaternionFromEuler(part.rpy),
            physicsClientId=self._client,
        )
        return int(vid)

    def create(self, x: float, y: float, heading: float) -> int:
        """A new NAO standing at (x, y) facing ``heading``; returns the body id.

        Link 0 is the head (revolute about z, :data:`HEAD_JOINT`); the other links are
        fixed parts.
        """
        vis = [self._head_root, *self._head_shapes, *self._body_shapes]
        pos = [(0.0, 0.0, NECK_Z)] + [p.pos for p in HEAD_PARTS[1:]] + [p.pos for p in BODY_PARTS]
        parents = [0] + [1] * (len(HEAD_PARTS) - 1) + [0] * len(BODY_PARTS)
        joints = [pb.JOINT_REVOLUTE] + [pb.JOINT_FIXED] * (len(vis) - 1)
        k = len(vis)
        body = pb.createMultiBody(
            baseMass=0.0,
            baseCollisionShapeIndex=-1,
            baseVisualShapeIndex=-1,
            basePosition=(x, y, 0.0),
            baseOrientation=pb.getQuaternionFromEuler((0.0, 0.0, heading)),
            linkMasses=[0.0] * k,
            linkCollisionShapeIndices=[-1] * k,
            linkVisualShapeIndices=vis,
            linkPositions=pos,
            linkOrientations=[(0.0, 0.0, 0.0, 1.0)] * k,
            linkInertialFramePositions=[(0.0, 0.0, 0.0)] * k,
            linkInertialFrameOrientations=[(0.0, 0.0, 0.0, 1.0)] * k,
            linkParentIndices=parents,
            linkJointTypes=joints,
            linkJointAxis=[(0.0, 0.0, 1.0)] * k,
            physicsClientId=self._client,
        )
        return int(body)


HEAD_JOINT = 0


def link_colours(
    orange: tuple[float, float, float, float] = ORANGE,
) -> tuple[tuple[float, float, float, float], ...]:
    """Each link's colour, in link order (:meth:`NaoBodyFactory.create`), the orange parts
    in ``orange``: a hidden NAO (:meth:`sim.physics.world.World.render` culls those out of view)
    gets them back."""
    return tuple(orange if p.rgba == ORANGE else p.rgba for p in (*HEAD_PARTS, *BODY_PARTS))


LINK_COLOURS = link_colours()
#: Radius (m) of a vertical cylinder about the body's axis that holds every part, whatever
#: the head's yaw: a NAO farther than that outside the camera's view draws no pixel.
BOUNDING_RADIUS = max(
    math.hypot(p.pos[0], p.pos[1]) + max(p.size) for p in (*HEAD_PARTS, *BODY_PARTS)
)
