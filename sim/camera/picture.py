"""A rendered camera picture developed in a look: light, colour temperature, motion blur,
auto exposure and sensor noise (docs/world.md "Looks"; docs/design.md §4). numpy only.

The renderer draws a clean, evenly lit scene; :func:`develop` turns it into what a camera
would deliver under a :class:`sim.camera.look.Look`, in the order light reaches the sensor:

1. **light** (``light``): every value times F, the room's light level;
2. **colour temperature** (``warm``): red times (1 + 0.3 w), blue times (1 - 0.3 w);
3. **motion blur** (``blur``): when the head turned since the robot's last picture, the
   picture is the mean of itself shifted by 0..PX-1 pixels along the rows, the way the
   scene came: a head turning left moves the scene right in the image, so what a pixel
   saw earlier in the exposure is what lies to its right at the end; edges repeat the
   border pixel;
4. **auto exposure** (``exposure``): one gain, target / mean brightness (Rec. 601 luma
   of the picture so far), held within [1/8, 8] (:data:`AE_GAIN_MIN`,
   :data:`AE_GAIN_MAX`) as a camera's exposure and gain range hold it: the mean
   reaches the target unless the scene is too dark or too bright for that range;
5. **sensor noise** (``noise``): Gaussian, σ grey levels, independent per pixel and
   channel, from a generator seeded by (scenario seed, look seed, robot id, frame
   number), so the same run gives the same pictures wherever they are drawn;

then rounded and clipped to 8 bits once. The default look returns the picture itself,
untouched (bit for bit today's).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.camera.look import WARM_GAIN, Look

AE_GAIN_MIN = 1.0 / 8.0
AE_GAIN_MAX = 8.0
#: Rec. 601 luma weights in BGR order.
LUMA_BGR = np.array([0.114, 0.587, 0.299], dtype=np.float32)
_NOISE_STREAM = 0x4E015E


@dataclass(frozen=True)
class Shot:
    """One picture of robot ``robot_id``: its ``frame`` number (0, 1, ... per robot) and
    how far (rad) its head ``turned`` since its previous picture (+: to its left)."""

    robot_id: int
    frame: int
    turned: float = 0.0


def develop(img: np.ndarray, look: Look, shot: Shot, seed: int = 0) -> np.ndarray:
    """``img`` (H, W, 3) uint8 BGR as a camera in ``look`` delivers it (module docstring);
    ``seed``: the scenario's. The default look returns ``img`` itself."""
    if not look.develops():
        return img
    out = img.astype(np.float32)
    if look.light != 1.0:
        out *= np.float32(look.light)
    if look.warm != 0.0:
        gains = np.array(
            [1.0 - WARM_GAIN * look.warm, 1.0, 1.0 + WARM_GAIN * look.warm], dtype=np.float32
        )
        out *= gains
    if look.blur > 1 and shot.turned != 0.0:
        out = smear(out, look.blur, 1 if shot.turned > 0 else -1)
    if look.exposure is not None:
        out *= np.float32(exposure_gain(out, look.exposure))
    if look.noise > 0:
        rng = np.random.default_rng([seed, look.seed, shot.robot_id, shot.frame, _NOISE_STREAM])
        out += rng.standard_normal(out.shape, dtype=np.float32) * np.float32(look.noise)
    return np.ascontiguousarray(np.clip(np.rint(out), 0, 255).astype(np.uint8))


def smear(img: np.ndarray, px: int, direction: int) -> np.ndarray:
    """Each pixel the mean of the ``px`` pixels from it towards the right of its row
    (``direction`` +1, the head turned left) or towards the left (-1); borders repeated."""
    h, w = img.shape[:2]
    pad = np.pad(img, ((0, 0), (px - 1, px - 1), (0, 0)), mode="edge")
    csum = np.cumsum(pad, axis=1, dtype=np.float64)
    csum = np.concatenate([np.zeros((h, 1, img.shape[2])), csum], axis=1)
    # column j is column j + px - 1 of pad: the window starts there (+1) or ends there (-1)
    start = np.arange(w) + (px - 1 if direction > 0 else 0)
    total = csum[:, start + px, :] - csum[:, start, :]
    return (total / px).astype(np.float32)


def exposure_gain(img: np.ndarray, target: float) -> float:
    """The auto exposure's gain: ``target`` / mean luma, within [AE_GAIN_MIN, AE_GAIN_MAX]."""
    mean = float((img.reshape(-1, 3) @ LUMA_BGR).mean())
    if mean <= 0.0:
        return AE_GAIN_MAX
    return min(AE_GAIN_MAX, max(AE_GAIN_MIN, target / mean))
