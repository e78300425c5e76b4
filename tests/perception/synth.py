"""Synthetic NAO-like pictures drawn with OpenCV for the pure perception tests.

A stand-in for the world's renderer that keeps the unit tests independent of it: an
orange head cap above two orange shoulder covers whose spacing shrinks with |cos θ|;
near the side posture one shoulder is hidden (2 tuples).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from agent.core.perception.mbase import MBase, cut_mask

ORANGE_BGR = (0, 60, 255)  # H ≈ 7, S 255, V 255 on OpenCV's scale
GREY_BGR = (128, 128, 128)


def draw_nao(
    img: np.ndarray, cx: float, top: float, scale: float, theta: float, color: tuple = ORANGE_BGR
) -> None:
    """Draw head + shoulders with the head cap's top at row ``top``, centred at ``cx``."""
    s = scale
    c = abs(math.cos(theta))
    head = (round(cx), round(top + 24 * s))
    cv2.ellipse(img, head, (round(34 * s), round(24 * s)), 0, 0, 360, color, -1)
    spread = 60 + 55 * c
    shoulders = [-1, 1] if c > 0.3 else [1 if math.sin(theta) > 0 else -1]
    for side in shoulders:
        centre = (round(cx + side * spread * s), round(top + 95 * s))
        axes = (round((14 + 16 * c) * s), round(26 * s))
        cv2.ellipse(img, centre, axes, 0, 0, 360, color, -1)


def canvas(w: int = 640, h: int = 480, bgr: tuple = GREY_BGR) -> np.ndarray:
    img = np.zeros((h, w, 3), np.uint8)
    img[:] = bgr
    return img


def synthetic_mbase(orientations_deg: list[float], horizon_row: float = 229.0) -> MBase:
    """An M-base of drawn masks at scale 1, centred at column 320, top at horizon - 40."""
    masks, ns, tops, cents = [], [], [], []
    for deg in orientations_deg:
        m = np.zeros((480, 640), np.uint8)
        draw_nao_mask(m, 320.0, horizon_row - 40.0, 1.0, math.radians(deg))
        cut = cut_mask(m, horizon_row, 320.0)
        masks.append(cut.crop)
        ns.append(cut.n_tuples)
        tops.append(cut.top_offset)
        cents.append(cut.centre_offset)
    return MBase(
        masks=masks,
        orientation=np.radians(orientations_deg),
        side=[n == 2 for n in ns],
        n_tuples=ns,
        top_offset=tops,
        centre_offset=cents,
        meta={"synthetic": True},
    )


def draw_nao_mask(m: np.ndarray, cx: float, top: float, scale: float, theta: float) -> None:
    """The same shapes as :func:`draw_nao`, drawn in 255 on a binary image."""
    rgb = np.zeros((*m.shape, 3), np.uint8)
    draw_nao(rgb, cx, top, scale, theta, color=(255, 255, 255))
    m[rgb[:, :, 0] > 0] = 255


def textured_panorama(seed: int, fx: float, height: int = 480) -> np.ndarray:
    """A seeded random-blob texture covering 360° of azimuth at ``fx`` px per rad."""
    rng = np.random.default_rng(seed)
    w = math.ceil(2 * math.pi * fx)
    pano = np.full((height + 200, w, 3), 90, np.uint8)
    for _ in range(2500):
        x, y = int(rng.integers(0, w)), int(rng.integers(0, height + 200))
        r = int(rng.integers(3, 18))
        col = tuple(int(v) for v in rng.integers(0, 256, 3))
        if rng.random() < 0.5:
            cv2.circle(pano, (x, y), r, col, -1)
        else:
            cv2.rectangle(pano, (x, y), (x + 2 * r, y + r), col, -1)
    return pano


def view_of_panorama(pano: np.ndarray, yaw: float, fx: float, fy: float) -> np.ndarray:
    """The 640x480 perspective view of a cylindrical panorama around the camera at ``yaw``
    (rad, +CCW): a CCW turn moves the scene to the right in the image."""
    w, h = 640, 480
    cx, cy = w / 2.0, h / 2.0
    u = np.arange(w, dtype=np.float64)
    v = np.arange(h, dtype=np.float64)
    x = (u - cx) / fx
    az = np.arctan(x)  # rightwards angle of each column
    pw = pano.shape[1]
    col = (pw / 2.0 - fx * yaw + fx * az) % pw
    row = (pano.shape[0] / 2.0) + fy * ((v[:, None] - cy) / fy) / np.sqrt(1 + x[None, :] ** 2)
    map_x = np.broadcast_to(col[None, :], (h, w)).astype(np.float32)
    map_y = row.astype(np.float32)
    return cv2.remap(pano, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
