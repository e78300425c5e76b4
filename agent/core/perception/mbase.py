"""The M-base: the mask base of NAO appearances (NAO paper 3.1.2 and 5.2.2 (i)).

One mask per relative orientation θ of the observed NAO (72 masks, 5° apart, rendered at
d_s = 0.6 m with head yaw 0), plus the supplementary "side"-posture masks. A mask is the
binary image of the head cap and the two shoulder covers (2 tuples for side postures),
cropped to their common bounding box, taken from the *cylindrical* image (see
``camera.py``). Besides the binary crop each mask keeps its number of tuples, its box
size and the offset of its box from the horizon row, which the recognition uses to
reject implausible tuple groups.

File format (versioned): ``mbase.npz`` with the crops bit-packed into one padded stack,
and ``mbase.json`` with the parameters that made it and a content digest.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

MBASE_VERSION = 1
DATA_DIR = Path(__file__).resolve().parent / "data"
CANON_W = 48
CANON_H = 32


def canonical(binary: np.ndarray) -> np.ndarray:
    """A crop resampled to the common ``CANON_W x CANON_H`` size, as a unit float vector."""
    if binary.ndim != 2 or binary.shape[0] < 1 or binary.shape[1] < 1:
        raise ValueError(f"crop must be a non-empty 2-D array, got shape {binary.shape}")
    small = cv2.resize(binary.astype(np.float32), (CANON_W, CANON_H), interpolation=cv2.INTER_AREA)
    v = small.reshape(-1).astype(np.float64)
    n = float(np.linalg.norm(v))
    if n == 0.0:
        raise ValueError("crop has no foreground pixels")
    return v / n


def part_shares(binary: np.ndarray) -> np.ndarray:
    """Area shares of a mask's connected parts (8-connected), largest first; sums to 1."""
    n, _, stats, _ = cv2.connectedComponentsWithStats((binary > 0).astype(np.uint8), connectivity=8)
    areas = np.sort(stats[1:n, cv2.CC_STAT_AREA].astype(np.float64))[::-1]
    if areas.size == 0:
        raise ValueError("mask has no foreground pixels")
    return np.asarray(areas / areas.sum())


@dataclass
class MBase:
    """The mask base. ``masks[k]`` is a 0/1 uint8 crop; per-mask arrays are indexed by k.

    ``orientation`` (rad, [0, 2π)) is the observed NAO's heading minus the observer's
    viewing direction (common.md); ``top_offset`` is the crop's top row minus the horizon
    row and ``centre_offset`` the column of the NAO's body centre minus the crop's centre
    column (px, at d_s; both scale with r_g); ``meta`` holds the generating parameters.
    """

    masks: list[np.ndarray]
    orientation: np.ndarray
    side: np.ndarray
    n_tuples: np.ndarray
    top_offset: np.ndarray
    centre_offset: np.ndarray
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        k = len(self.masks)
        if k == 0:
            raise ValueError("an M-base needs at least one mask")
        self.orientation = np.asarray(self.orientation, dtype=np.float64).reshape(-1)
        self.side = np.asarray(self.side, dtype=bool).reshape(-1)
        self.n_tuples = np.asarray(self.n_tuples, dtype=np.int64).reshape(-1)
        self.top_offset = np.asarray(self.top_offset, dtype=np.float64).reshape(-1)
        self.centre_offset = np.asarray(self.centre_offset, dtype=np.float64).reshape(-1)
        for name in ("orientation", "side", "n_tuples", "top_offset", "centre_offset"):
            if getattr(self, name).shape != (k,):
                raise ValueError(f"M-base {name} must have {k} entries")
        masks = []
        for i, m in enumerate(self.masks):
            m = np.asarray(m)
            if m.ndim != 2 or m.size == 0 or not np.any(m):
                raise ValueError(f"M-base mask {i} is empty or not 2-D")
            masks.append((m > 0).astype(np.uint8))
        self.masks = masks
        self.sizes = np.array([[m.shape[1], m.shape[0]] for m in masks], dtype=np.float64)
        self.canon = np.stack([canonical(m) for m in masks])
        self.canon32 = self.canon.astype(np.float32)
        self.areas = np.array([float(m.sum()) for m in masks])
        self.part_shares = [part_shares(m) for m in masks]

    def __len__(self) -> int:
        return len(self.masks)

    def digest(self) -> str:
        """SHA-256 of the mask content (crops, orientations, flags, offsets)."""
        h = hashlib.sha256()
        for m in self.masks:
            h.update(np.array(m.shape, dtype=np.int64).tobytes())
            h.update(np.ascontiguousarray(m, dtype=np.uint8).tobytes())
        for arr in (self.orientation, self.top_offset, self.centre_offset):
            h.update(np.round(arr, 9).astype(np.float64).tobytes())
        h.update(self.side.astype(np.uint8).tobytes())
        h.update(self.n_tuples.astype(np.int64).tobytes())
        return h.hexdigest()

    def save(self, directory: Path, stem: str = "mbase") -> tuple[Path, Path]:
        """Write ``stem.npz`` and ``stem.json`` into ``directory``."""
        directory.mkdir(parents=True, exist_ok=True)
        hmax = max(m.shape[0] for m in self.masks)
        wmax = max(m.shape[1] for m in self.masks)
        stack = np.zeros((len(self), hmax, wmax), dtype=np.uint8)
        for i, m in enumerate(self.masks):
            stack[i, : m.shape[0], : m.shape[1]] = m
        npz = directory / f"{stem}.npz"
        np.savez_compressed(
            npz,
            packed=np.packbits(stack, axis=-1),
            wmax=np.int64(wmax),
            sizes=self.sizes.astype(np.int64),
            orientation=self.orientation,
            side=self.side,
            n_tuples=self.n_tuples,
            top_offset=self.top_offset,
            centre_offset=self.centre_offset,
        )
        meta = dict(self.meta)
        meta.update({"version": MBASE_VERSION, "count": len(self), "digest": self.digest()})
        js = directory / f"{stem}.json"
        js.write_text(json.dumps(meta, indent=2, sort_keys=True) + "\n")
        return npz, js

    @classmethod
    def load(cls, directory: Path | None = None, stem: str = "mbase") -> MBase:
        """Read an M-base written by :meth:`save` (default: the packaged one)."""
        directory = DATA_DIR if directory is None else Path(directory)
        npz, js = directory / f"{stem}.npz", directory / f"{stem}.json"
        if not npz.is_file() or not js.is_file():
            raise ValueError(f"no M-base at {npz} / {js}: run python -m tools.build_mbase")
        meta = json.loads(js.read_text())
        if meta.get("version") != MBASE_VERSION:
            raise ValueError(f"M-base version {meta.get('version')} != {MBASE_VERSION}")
        with np.load(npz) as z:
            stack = np.unpackbits(z["packed"], axis=-1, count=int(z["wmax"]))
            sizes = z["sizes"]
            masks = [stack[i, : int(h), : int(w)].copy() for i, (w, h) in enumerate(sizes)]
            mb = cls(
                masks=masks,
                orientation=z["orientation"],
                side=z["side"],
                n_tuples=z["n_tuples"],
                top_offset=z["top_offset"],
                centre_offset=z["centre_offset"],
                meta=meta,
            )
        if meta.get("digest") != mb.digest():
            raise ValueError(f"M-base {npz} does not match the digest in {js}")
        return mb


def orientation_deg(mb: MBase, k: int) -> float:
    """Mask ``k``'s orientation in whole degrees (for tables)."""
    return round(math.degrees(float(mb.orientation[k])), 3)


@dataclass(frozen=True)
class MaskSample:
    """One mask cut from a cylindrical orange mask of a lone NAO at d_s (3.1.2 (4))."""

    crop: np.ndarray
    n_tuples: int
    top_offset: float
    centre_offset: float


def cut_mask(
    cyl_mask: np.ndarray,
    horizon_row: float,
    centre_col: float,
    min_area: int = 12,
    drop_smallest: bool = False,
) -> MaskSample:
    """Cut the mask of the one NAO in ``cyl_mask`` (its tuples near the image centre).

    ``centre_col`` is the column where the NAO's body centre projects; the tuples kept
    are those whose centroid lies within half the image width of it. ``drop_smallest``
    leaves out the smallest tuple (ties: the later in sorted order): the look of a NAO
    whose sliver of a far shoulder vanishes with distance.
    """
    from agent.core.perception.segmentation import extract_tuples

    labels, tuples = extract_tuples(cyl_mask, min_area=min_area)
    half = cyl_mask.shape[1] / 2.0
    keep = [t for t in tuples if abs(t.cx - centre_col) < half]
    if drop_smallest and len(keep) >= 2:
        small = min(range(len(keep)), key=lambda i: (keep[i].area, -i))
        keep = keep[:small] + keep[small + 1 :]
    if not keep:
        raise ValueError("no orange tuple near the image centre: is the NAO in view?")
    x0 = min(t.box[0] for t in keep)
    y0 = min(t.box[1] for t in keep)
    x1 = max(t.box[0] + t.box[2] for t in keep)
    y1 = max(t.box[1] + t.box[3] for t in keep)
    ids = np.array([t.label for t in keep], dtype=labels.dtype)
    crop = np.isin(labels[y0:y1, x0:x1], ids).astype(np.uint8)
    return MaskSample(
        crop=crop,
        n_tuples=len(keep),
        top_offset=float(y0 - horizon_row),
        centre_offset=float(centre_col - (x0 + x1) / 2.0),
    )
