"""The NAO forehead camera (NAO paper §3, Fig. 1; docs/design.md §4).

A pinhole camera, 640 x 480, horizontal FOV 60.9°, vertical 47.6° (square pixels,
fx = fy = 320 / tan(30.45°) ≈ 543.9 px, principal point at the image centre), at
:data:`CAMERA_Z` = 0.50 m above the floor, 6.2 cm in front of the head yaw
axis, pitched down 1.2°. The head yaws within ±119.5° (positive = to the robot's left);
a request outside that range is an error, never a clamp. Rendered by PyBullet's CPU
TinyRenderer or its EGL plugin (:mod:`sim.camera.renderer`) and returned as a (480, 640, 3)
uint8 BGR array (OpenCV order).

:func:`project` is the same camera model in closed form: where a world point lands in
the image (used by tests to check the renderer against the model).
"""

from __future__ import annotations

import math

import numpy as np
import pybullet as pb

from agent.wire import nao

# The NAO's numbers have one home, agent/core/nao.py (reached through agent.wire).
CAMERA_Z = nao.CAMERA_HEIGHT_M
CAMERA_FORWARD = nao.CAMERA_FORWARD
WIDTH = nao.CAMERA_WIDTH
HEIGHT = nao.CAMERA_HEIGHT
HFOV = nao.CAMERA_HFOV
FX = (WIDTH / 2) / math.tan(HFOV / 2)
FY = FX  # square pixels: the vertical FOV follows (47.6°, nao.CAMERA_VFOV)
VFOV = 2.0 * math.atan((HEIGHT / 2) / FY)
PITCH = nao.CAMERA_PITCH_DOWN  # downwards
YAW_LIMIT = nao.HEAD_YAW_LIMIT
NEAR = 0.02
FAR = 30.0
#: The EGL plugin's depth buffer has 16 bits: with the near plane at 2 cm its steps reach
#: 6 mm at 2.8 m, and the head (r 60 mm) showed through the orange cap (r 63 mm) of far
#: NAOs. At 8 cm the steps are 4 times finer; nothing comes nearer the camera (a NAO
#: stops 15.5 cm from a wall, its camera 6.2 cm in front of its axis).
NEAR_EGL = 0.08


def check_yaw(yaw: float) -> float:
    """``yaw`` as float if it is a finite head yaw within ±119.5°, else ``ValueError``."""
    y = float(yaw)
    if not math.isfinite(y):
        raise ValueError(f"head yaw {yaw!r} is not finite")
    if abs(y) > YAW_LIMIT + 1e-9:
        raise ValueError(f"head yaw {math.degrees(y):.2f}° outside ±{math.degrees(YAW_LIMIT):.1f}°")
    return y


def camera_pose(
    x: float, y: float, heading: float, yaw: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Eye position, unit forward (optical axis) and unit up vectors in the world."""
    psi = heading + yaw
    c, s = math.cos(psi), math.sin(psi)
    eye = np.array([x + CAMERA_FORWARD * c, y + CAMERA_FORWARD * s, CAMERA_Z])
    cp, sp = math.cos(PITCH), math.sin(PITCH)
    fwd = np.array([cp * c, cp * s, -sp])
    up = np.array([sp * c, sp * s, cp])
    return eye, fwd, up


def project(x: float, y: float, heading: float, yaw: float, points: np.ndarray) -> np.ndarray:
    """Pixel coordinates (u right, v down) of world ``points`` (K, 3); NaN behind the camera."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    eye, fwd, up = camera_pose(x, y, heading, yaw)
    right = np.cross(fwd, up)
    rel = pts - eye
    z = rel @ fwd
    u = WIDTH / 2 + FX * (rel @ right) / z
    v = HEIGHT / 2 - FY * (rel @ up) / z
    out = np.stack([u, v], axis=1)
    out[z <= 1e-9] = np.nan
    return out


PROJECTION = pb.computeProjectionMatrixFOV(
    fov=math.degrees(VFOV), aspect=WIDTH / HEIGHT, nearVal=NEAR, farVal=FAR
)


def _shifted(proj: tuple[float, ...], du: float, dv: float) -> tuple[float, ...]:
    """``proj`` (column-major 4x4) moving the picture ``du`` px right and ``dv`` px down."""
    m = list(proj)
    m[8] += (2.0 * du / WIDTH) * m[11]  # x_ndc += 2 du / W (w_clip = -z_eye)
    m[9] -= (2.0 * dv / HEIGHT) * m[11]  # y_ndc -= 2 dv / H (image rows run down)
    return tuple(m)


#: OpenGL samples a pixel at its centre, TinyRenderer at its corner: the EGL plugin's
#: picture sits half a pixel left of and below TinyRenderer's (measured by phase
#: correlation, ``tests/sim/camera/test_renderer.py``); this projection moves it back.
PROJECTION_EGL = _shifted(
    pb.computeProjectionMatrixFOV(
        fov=math.degrees(VFOV), aspect=WIDTH / HEIGHT, nearVal=NEAR_EGL, farVal=FAR
    ),
    0.5,
    -0.5,
)


def render(
    client: int,
    x: float,
    y: float,
    heading: float,
    yaw: float,
    *,
    light_direction: tuple[float, float, float],
    light_intensity: float,
    renderer: int = pb.ER_TINY_RENDERER,
) -> np.ndarray:
    """Render the forehead camera of a robot at (x, y, heading) with head ``yaw``.

    ``renderer``: ``pb.ER_TINY_RENDERER``, or ``pb.ER_BULLET_HARDWARE_OPENGL`` in a client
    with the EGL plugin (:mod:`sim.camera.renderer`; it ignores the light coefficients).
    Returns a (480, 640, 3) uint8 BGR image.
    """
    yaw = check_yaw(yaw)
    eye, fwd, up = camera_pose(x, y, heading, yaw)
    view = pb.computeViewMatrix(
        cameraEyePosition=eye.tolist(),
        cameraTargetPosition=(eye + fwd).tolist(),
        cameraUpVector=up.tolist(),
    )
    _, _, rgba, _, _ = pb.getCameraImage(
        WIDTH,
        HEIGHT,
        viewMatrix=view,
        projectionMatrix=PROJECTION if renderer == pb.ER_TINY_RENDERER else PROJECTION_EGL,
        renderer=renderer,
        lightDirection=light_direction,
        lightColor=(1.0, 1.0, 1.0),
        lightDistance=10.0,
        shadow=0,
        lightAmbientCoeff=0.62 * light_intensity,
        lightDiffuseCoeff=0.38 * light_intensity,
        lightSpecularCoeff=0.0,
        flags=pb.ER_NO_SEGMENTATION_MASK,
        physicsClientId=client,
    )
    img = np.asarray(rgba, dtype=np.uint8).reshape(HEIGHT, WIDTH, 4)
    return np.ascontiguousarray(img[:, :, 2::-1])
