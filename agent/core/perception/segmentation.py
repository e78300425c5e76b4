"""Orange segmentation and tuple extraction (NAO paper 3.1.1, 3.1.3, Figures 4 and 7).

The image is thresholded in HSV with the paper's orange range (H 2-10, S >= 170,
V >= 50 on OpenCV's 0-180 hue scale), the noise is filtered with a Gaussian filter and a
morphological closing and opening, and the connected components of what remains are
the "tuples" (head cap and shoulder covers of each NAO, plus any orange clutter).

The range is an :class:`OrangeRange`: the paper's by default (:data:`ORANGE`), or one
learnt from a lab's own robots (``python -m tools.calibrate build``; a calibration
folder's ``orange.json``, :mod:`agent.core.perception.calibration`). A hue range whose
low end is above its high end wraps through red (e.g. H 172-4).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

HSV_LOW = (2, 170, 50)
HSV_HIGH = (10, 255, 255)
MIN_IMAGE_SIDE = 16
HUE_MAX = 179  # OpenCV's 8-bit hue scale: 0-179 (degrees / 2)


@dataclass(frozen=True)
class OrangeRange:
    """HSV thresholds of the orange (OpenCV scale: H 0-179, S and V 0-255).

    ``low`` and ``high`` are (H, S, V); S and V need ``low <= high``; a hue with
    ``low[0] > high[0]`` wraps through 0 (red).
    """

    low: tuple[int, int, int] = HSV_LOW
    high: tuple[int, int, int] = HSV_HIGH

    def __post_init__(self) -> None:
        for name in ("low", "high"):
            v = getattr(self, name)
            if (
                not isinstance(v, tuple | list)
                or len(v) != 3
                or not all(isinstance(x, int) and not isinstance(x, bool) for x in v)
            ):
                raise ValueError(f"orange {name} must be three ints (H, S, V), got {v!r}")
            object.__setattr__(self, name, tuple(int(x) for x in v))
        (h0, s0, v0), (h1, s1, v1) = self.low, self.high
        if not (0 <= h0 <= HUE_MAX and 0 <= h1 <= HUE_MAX):
            raise ValueError(f"orange hue must be in [0, {HUE_MAX}], got {h0} and {h1}")
        if not (0 <= s0 <= s1 <= 255 and 0 <= v0 <= v1 <= 255):
            raise ValueError(
                f"orange S and V must satisfy 0 <= low <= high <= 255, got S {s0}-{s1}, V {v0}-{v1}"
            )

    @property
    def wraps(self) -> bool:
        """The hue range runs through 0 (red)."""
        return self.low[0] > self.high[0]

    def to_dict(self) -> dict[str, list[int]]:
        return {"hsv_low": list(self.low), "hsv_high": list(self.high)}

    @classmethod
    def from_dict(cls, doc: object) -> OrangeRange:
        """The range of ``{"hsv_low": [H, S, V], "hsv_high": [H, S, V]}`` (``ValueError``)."""
        if not isinstance(doc, dict) or not {"hsv_low", "hsv_high"} <= set(doc):
            raise ValueError('expected {"hsv_low": [H, S, V], "hsv_high": [H, S, V]}')
        low, high = doc["hsv_low"], doc["hsv_high"]
        if not isinstance(low, list) or not isinstance(high, list):
            raise ValueError("hsv_low and hsv_high must be lists of three ints")
        return cls(tuple(low), tuple(high))

    def within(self, hsv: np.ndarray) -> np.ndarray:
        """0/255 uint8 mask of the pixels of an HSV image inside the range."""
        lo, hi = np.array(self.low, np.uint8), np.array(self.high, np.uint8)
        if not self.wraps:
            return cv2.inRange(hsv, lo, hi)
        top = np.array((HUE_MAX, hi[1], hi[2]), np.uint8)
        bottom = np.array((0, lo[1], lo[2]), np.uint8)
        return cv2.bitwise_or(cv2.inRange(hsv, lo, top), cv2.inRange(hsv, bottom, hi))


#: The paper's orange (the built-in calibration's)
ORANGE = OrangeRange()


@dataclass(frozen=True)
class Tuple:
    """One connected orange component: centroid (px), box (x, y, w, h) and area (px)."""

    label: int
    cx: float
    cy: float
    box: tuple[int, int, int, int]
    area: int


def check_image(image_bgr: object) -> np.ndarray:
    """Validate a BGR uint8 image of shape (h, w, 3); raise ``ValueError`` otherwise."""
    if not isinstance(image_bgr, np.ndarray):
        raise ValueError(f"image must be a numpy array, got {type(image_bgr).__name__}")
    if image_bgr.size == 0:
        raise ValueError(f"image is empty (shape {image_bgr.shape})")
    if image_bgr.ndim != 3 or image_bgr.shape[2] != 3:
        raise ValueError(f"image must have shape (h, w, 3) BGR, got {image_bgr.shape}")
    if image_bgr.dtype != np.uint8:
        raise ValueError(f"image must be uint8, got {image_bgr.dtype}")
    h, w = image_bgr.shape[:2]
    if h < MIN_IMAGE_SIDE or w < MIN_IMAGE_SIDE:
        raise ValueError(f"image {w}x{h} is too small (min {MIN_IMAGE_SIDE}x{MIN_IMAGE_SIDE})")
    return np.ascontiguousarray(image_bgr)


def orange_mask(
    image_bgr: np.ndarray, blur: int = 3, morph: int = 3, orange: OrangeRange = ORANGE
) -> np.ndarray:
    """Binary (0/255 uint8) mask of the orange pixels after filtering.

    ``blur`` is the Gaussian kernel size applied to the colour image before the HSV
    threshold ``orange``, ``morph`` the size of the elliptic kernel of the closing then
    opening (0 disables either).
    """
    img = check_image(image_bgr)
    if blur < 0 or morph < 0 or (blur and blur % 2 == 0):
        raise ValueError(f"blur must be 0 or odd and morph >= 0, got blur={blur} morph={morph}")
    if blur:
        img = cv2.GaussianBlur(img, (blur, blur), 0)
    hsv = cv2.cvtColor(img, cv2.COLOR_BGR2HSV)
    mask = orange.within(hsv)
    if morph:
        k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (morph, morph))
        mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, k)
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, k)
    return mask


def extract_tuples(mask: np.ndarray, min_area: int = 12) -> tuple[np.ndarray, list[Tuple]]:
    """Connected components (8-connected) of a binary mask with at least ``min_area`` pixels.

    Returns the label image (int32) and the tuples sorted by (x, y, label) of their box, so
    the order is deterministic.
    """
    if not isinstance(mask, np.ndarray) or mask.ndim != 2 or mask.size == 0:
        raise ValueError("mask must be a non-empty 2-D array")
    if min_area < 1:
        raise ValueError(f"min_area must be >= 1, got {min_area}")
    binary = (mask > 0).astype(np.uint8)
    n, labels, stats, cents = cv2.connectedComponentsWithStats(binary, connectivity=8)
    tuples = [
        Tuple(
            label=i,
            cx=float(cents[i, 0]),
            cy=float(cents[i, 1]),
            box=(
                int(stats[i, cv2.CC_STAT_LEFT]),
                int(stats[i, cv2.CC_STAT_TOP]),
                int(stats[i, cv2.CC_STAT_WIDTH]),
                int(stats[i, cv2.CC_STAT_HEIGHT]),
            ),
            area=int(stats[i, cv2.CC_STAT_AREA]),
        )
        for i in range(1, n)
        if stats[i, cv2.CC_STAT_AREA] >= min_area
    ]
    tuples.sort(key=lambda t: (t.box[0], t.box[1], t.label))
    return labels, tuples
