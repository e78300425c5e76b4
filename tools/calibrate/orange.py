"""The orange range from a lab's own pictures (NAO paper 3.1.1: the HSV thresholds of the
head caps and shoulder covers).

The M-base views have NAO-j alone at d_s straight along NAO-i's camera axis, so its caps
and shoulders lie in a known band of columns around the image centre (the ``window``:
NAO-j's half-width ``HALF_WIDTH`` at its distance) and nothing of it outside. Over those
images (blurred as the segmentation blurs them), the hue histogram of the saturated
pixels inside the window is compared with the one outside it, per pixel of area: the
hue where the window has the most surplus is the caps' hue, and the band of hues around
it that still has a surplus (``BAND_SHARE`` of the peak) is theirs. The pixels of that
band inside the window are the orange pixels.

Their saturation and value bound the range, a box in HSV: the hue band widened by
``HUE_MARGIN``; ceilings ``SV_MARGIN`` above the orange pixels' 99th percentiles of S and
V (``CEILING_TAIL``); and the floors that keep the most orange pixels while at most
``BACKGROUND_SHARE`` of the pixels outside the window pass, ties to the lower floors
(found exactly over every pair of floors from two-dimensional cumulative counts). The
range keeps at least ``MIN_KEPT`` of the orange pixels, and is as wide as the background
allows: a dim room, whose greys take a warm hue,
raises the floors; a room clear of the caps' colour leaves them low. When no floors keep
the background out, those that let the least through, and the build reports the share
(the recogniser's head-and-shoulders test, NAO paper 3.1.2, rejects a stray patch; the
check measures the outcome).
:func:`figure` draws the histograms with the range chosen.
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
SV_MARGIN = 40  # S and V above the caps' brightest, most saturated pixels the range allows
MIN_KEPT = 0.5  # the least share of the caps' pixels a range keeps, whatever passes
CEILING_TAIL = 1.0  # per cent of the caps' pixels above which the ceilings are set
BACKGROUND_SHARE = 2e-5
MIN_SURPLUS = 1e-3  # of the window's pixels: less, and no orange was seen
HUES = HUE_MAX + 1


@dataclass(frozen=True)
class OrangeFit:
    """The range and what it came from: hue histograms (per pixel) inside and outside the
    window, the orange pixels' S and V, the background share inside the range, the share of the
    orange pixels the range keeps."""

    orange: OrangeRange
    peak_hue: int
    inside: np.ndarray
    outside: np.ndarray
    s_values: np.ndarray
    v_values: np.ndarray
    background_share: float
    kept: float
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
    if not len(cand):
        raise ValueError("no pixel of the caps' hue is saturated and bright enough to measure")
    h0, h1 = (lo - HUE_MARGIN) % HUES, (hi + HUE_MARGIN) % HUES
    bgp = bgp[_in_band(bgp[:, 0], h0, h1)]  # the background that the hue band lets through
    n_bg = max(sum(len(b) for b in bg), 1)
    orange, bshare = _box(cand, bgp, n_bg, h0, h1)
    kept = float(np.mean(_inside(cand, orange)))
    return OrangeFit(
        orange, peak, inside, outside, cand[:, 1], cand[:, 2], bshare, kept, len(images)
    )


def _inside(px: np.ndarray, o: OrangeRange) -> np.ndarray:
    """Which of the in-band pixels ``px`` (N×3 HSV) the range's S and V bounds let through."""
    (_, s0, v0), (_, s1, v1) = o.low, o.high
    return (px[:, 1] >= s0) & (px[:, 1] <= s1) & (px[:, 2] >= v0) & (px[:, 2] <= v1)


def _box(
    caps: np.ndarray, background: np.ndarray, n_bg: int, h0: int, h1: int
) -> tuple[OrangeRange, float]:
    """The range of the module docstring: of the boxes with the ceilings of the caps'
    pixels (``caps``), the floors that keep the most of them (at least ``MIN_KEPT``) while at most
    ``BACKGROUND_SHARE`` of the ``n_bg`` background pixels pass (``background``: those in
    the hue band); ties to the lower floors, S before V. When no floors keep the
    background out, those that let the least through. Returns the range and its
    background share."""
    s_hi = _clip(np.percentile(caps[:, 1], 100 - CEILING_TAIL) + SV_MARGIN)
    v_hi = _clip(np.percentile(caps[:, 2], 100 - CEILING_TAIL) + SV_MARGIN)

    def at_least(px: np.ndarray) -> np.ndarray:
        """[s, v]: how many of ``px`` under the ceilings have S >= s and V >= v."""
        px = px[(px[:, 1] <= s_hi) & (px[:, 2] <= v_hi)]
        h = np.zeros((256, 256), np.int64)
        np.add.at(h, (px[:, 1].astype(np.intp), px[:, 2].astype(np.intp)), 1)
        out: np.ndarray = h[::-1, ::-1].cumsum(0).cumsum(1)[::-1, ::-1]
        return out

    kept, passed = at_least(caps), at_least(background)
    share = passed / n_bg
    enough = kept >= MIN_KEPT * len(caps)  # a range for the caps, not for nothing
    share = np.where(enough, share, np.inf)
    ok = share <= BACKGROUND_SHARE
    s_idx, v_idx = np.indices(share.shape)
    if ok.any():  # the most caps; then the lowest floors (sum), then the lower S
        score = np.where(ok, kept, -1)
        key = np.lexsort((s_idx.ravel(), (s_idx + v_idx).ravel(), -score.ravel()))
    else:  # the least background; then the most caps
        key = np.lexsort(((s_idx + v_idx).ravel(), -kept.ravel(), share.ravel()))
    s_lo, v_lo = np.unravel_index(int(key[0]), share.shape)
    o = OrangeRange((h0, int(s_lo), int(v_lo)), (h1, s_hi, v_hi))
    return o, float(share[s_lo, v_lo])


def _clip(x: float) -> int:
    return int(np.clip(round(x), 0, 255))


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
    (_, s1, v1) = fit.orange.high
    for ax, vals, bounds, name in (
        (ax2, fit.s_values, (s0, s1), "saturation"),
        (ax3, fit.v_values, (v0, v1), "value"),
    ):
        ax.hist(vals, bins=64, range=(0, 255), color="tab:orange")
        ax.axvspan(bounds[0], bounds[1], color="k", alpha=0.08)
        ax.axvline(bounds[0], color="k", ls="--", label=f"range {bounds[0]}-{bounds[1]}")
        ax.axvline(bounds[1], color="k", ls="--")
        ax.set_xlabel(f"{name} of the caps' pixels")
        ax.legend(fontsize=8)
    ax3.set_title(f"the range keeps {100 * fit.kept:.1f} % of the caps' pixels")
    ax2.set_title(f"{fit.images} views; background inside the range {fit.background_share:.1e}")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
