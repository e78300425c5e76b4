"""The orange range from a lab's own pictures (NAO paper 3.1.1: the HSV thresholds of the
head caps and shoulder covers).

The M-base views have NAO-j alone at d_s straight along NAO-i's camera axis, so its caps
and shoulders lie in a known band of columns around the image centre (the ``window``:
NAO-j's half-width ``HALF_WIDTH`` at its distance) and nothing of it outside. Over those
images (blurred as the segmentation blurs them), the hue histogram of the saturated
pixels inside the window is compared with the one outside it, per pixel of area: the
hue where the window has the most surplus is the caps' hue, and the band of hues around
it that still has a surplus (``BAND_SHARE`` of the peak) is theirs. The pixels of that
band inside the window are the orange pixels; the range is their hue band widened by
``HUE_MARGIN`` and their saturation and value floors (the ``FLOOR_PERCENTILE`` lowered by
``SV_MARGIN``), then raised while more than ``BACKGROUND_SHARE`` of the pixels outside the
window would pass. :func:`figure` draws the histograms with the range chosen.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from agent.core.perception.camera import CameraModel
from agent.core.perception.segmentation import HUE_MAX, OrangeRange

HALF_WIDTH = 0.25  # m: NAO-j's half-width with a margin (its arms)
S_PROBE, V_PROBE = 80, 40  # what counts as a coloured pixel at all
BAND_SHARE = 0.05
HUE_MARGIN = 2
FLOOR_PERCENTILE = 1.0
SV_MARGIN = 40
S_RANGE, V_RANGE = (80, 230), (30, 200)  # where the floors may end up
BACKGROUND_SHARE = 2e-5
MIN_SURPLUS = 1e-3  # of the window's pixels: less, and no orange was seen
HUES = HUE_MAX + 1


@dataclass(frozen=True)
class OrangeFit:
    """The range and what it came from: hue histograms (per pixel) inside and outside the
    window, the orange pixels' S and V, the background share inside the range."""

    orange: OrangeRange
    peak_hue: int
    inside: np.ndarray
    outside: np.ndarray
    s_values: np.ndarray
    v_values: np.ndarray
    background_share: float
    images: int


def _hsv(image: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(cv2.GaussianBlur(image, (3, 3), 0), cv2.COLOR_BGR2HSV)


def _in_band(h: np.ndarray, lo: int, hi: int) -> np.ndarray:
    return (h >= lo) & (h <= hi) if lo <= hi else (h >= lo) | (h <= hi)


def learn_orange(
    images: list[np.ndarray], distance: float, camera: CameraModel | None = None
) -> OrangeFit:
    """The orange range of NAO-j's caps in views taken at ``distance`` m (module
    docstring); ``ValueError`` when the views show no orange NAO."""
    if not images:
        raise ValueError("no M-base views to learn the orange from")
    cam = CameraModel() if camera is None else camera
    half = cam.fx * math.tan(math.atan(HALF_WIDTH / distance))
    cols = np.arange(cam.width)
    win = np.abs(cols - cam.cx) <= half
    inside, outside = np.zeros(HUES), np.zeros(HUES)
    n_in = n_out = 0
    fg: list[np.ndarray] = []
    bg: list[np.ndarray] = []
    for img in images:
        if img.shape[:2] != (cam.height, cam.width):
            raise ValueError(
                f"a view is {img.shape[1]}x{img.shape[0]}, not {cam.width}x{cam.height}"
            )
        hsv = _hsv(img)[::2, ::2]
        w = win[::2]
        a, b = hsv[:, w].reshape(-1, 3), hsv[:, ~w].reshape(-1, 3)
        n_in, n_out = n_in + len(a), n_out + len(b)
        for px, hist in ((a, inside), (b, outside)):
            keep = (px[:, 1] >= S_PROBE) & (px[:, 2] >= V_PROBE)
            hist += np.bincount(px[keep, 0], minlength=HUES)[:HUES]
        fg.append(a)
        bg.append(b)
    inside, outside = inside / max(n_in, 1), outside / max(n_out, 1)
    surplus = np.clip(inside - outside, 0.0, None)
    smooth = (np.roll(surplus, 1) + surplus + np.roll(surplus, -1)) / 3.0
    peak = int(np.argmax(smooth))
    if smooth[peak] < MIN_SURPLUS:
        raise ValueError(
            "no coloured caps stand out near the image centre of the M-base views: is "
            "NAO-j in front of NAO-i, and are its caps and shoulder covers on?"
        )
    lo = hi = peak
    for _ in range(HUES // 4):
        if smooth[(lo - 1) % HUES] > BAND_SHARE * smooth[peak]:
            lo = (lo - 1) % HUES
        elif smooth[(hi + 1) % HUES] > BAND_SHARE * smooth[peak]:
            hi = (hi + 1) % HUES
        else:
            break
    fgp, bgp = np.concatenate(fg), np.concatenate(bg)
    cand = fgp[_in_band(fgp[:, 0], lo, hi) & (fgp[:, 1] >= S_PROBE) & (fgp[:, 2] >= V_PROBE)]
    s_floor = int(np.clip(np.percentile(cand[:, 1], FLOOR_PERCENTILE) - SV_MARGIN, *S_RANGE))
    v_floor = int(np.clip(np.percentile(cand[:, 2], FLOOR_PERCENTILE) - SV_MARGIN, *V_RANGE))
    h0, h1 = (lo - HUE_MARGIN) % HUES, (hi + HUE_MARGIN) % HUES

    def share(s: int, v: int) -> float:
        hit = _in_band(bgp[:, 0], h0, h1) & (bgp[:, 1] >= s) & (bgp[:, 2] >= v)
        return float(hit.mean()) if len(bgp) else 0.0

    bshare = share(s_floor, v_floor)
    while bshare > BACKGROUND_SHARE and (s_floor < S_RANGE[1] or v_floor < V_RANGE[1]):
        s_floor = min(S_RANGE[1], s_floor + 10)
        v_floor = min(V_RANGE[1], v_floor + 10)
        bshare = share(s_floor, v_floor)
    orange = OrangeRange((h0, s_floor, v_floor), (h1, 255, 255))
    return OrangeFit(orange, peak, inside, outside, cand[:, 1], cand[:, 2], bshare, len(images))


def figure(fit: OrangeFit, path: Path) -> None:
    """The hue histograms inside and outside the window, the orange pixels' S and V, and
    the range chosen (shaded)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fig, (ax1, ax2, ax3) = plt.subplots(1, 3, figsize=(13, 3.6))
    hues = np.arange(HUES)
    ax1.plot(hues, fit.inside, label="near the image centre (NAO-j)")
    ax1.plot(hues, fit.outside, label="elsewhere (background)")
    (h0, s0, v0), (h1, _, _) = fit.orange.low, fit.orange.high
    spans = [(h0, h1)] if h0 <= h1 else [(h0, HUE_MAX), (0, h1)]
    for a, b in spans:
        ax1.axvspan(a - 0.5, b + 0.5, color="orange", alpha=0.3)
    ax1.set_yscale("log")
    ax1.set_xlabel("hue (OpenCV, 0-179)")
    ax1.set_ylabel(f"share of pixels (S >= {S_PROBE}, V >= {V_PROBE})")
    ax1.set_title(f"Hue: range {h0}-{h1} (peak {fit.peak_hue})")
    ax1.legend(fontsize=8)
    for ax, vals, floor, name in (
        (ax2, fit.s_values, s0, "saturation"),
        (ax3, fit.v_values, v0, "value"),
    ):
        ax.hist(vals, bins=64, range=(0, 255), color="tab:orange")
        ax.axvline(floor, color="k", ls="--", label=f"floor {floor}")
        ax.set_xlabel(f"{name} of the caps' pixels")
        ax.legend(fontsize=8)
    ax2.set_title(f"{fit.images} views; background inside the range {fit.background_share:.1e}")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
