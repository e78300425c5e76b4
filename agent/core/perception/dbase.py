"""The distance model d = a / r_g + b and its D-base (NAO paper 3.2.3 eq. 6, 5.2.1, Table 1).

One coefficient set per M-base mask, fitted by least squares (scipy) on the samples
(r_g, d) of the NAO placed at distances from 0.5 m to beyond 3 m (the paper: 20 distances
in [0.5, 1.45] m). The distance is measured from the observer's optical centre to the
observed NAO's body centre; the detector turns it into a body-relative position.

Extended range. Eq. 6 assumes the group's box shrinks exactly as 1/d. Far away a blob
loses a roughly constant pixel rim to the blur, the HSV threshold and the opening, so
the measured scale is r_g = k/d - δ/w_m rather than k/d. Eq. 6 with that offset,
``d = a / (r_g + c) + b``, is what is fitted (c ≈ δ/w_m, a few thousandths; c = 0 is the
paper's model, and a version-1 file reads as c = 0). Over 0.5-1.45 m c is not
identifiable and the fit keeps c = 0.

Scale. Algorithm 1's r_g is min(w_g/w_m, h_g/h_m). Its width ratio follows the matched
mask's orientation, and the orientation of a NAO with its head turned, or seen far away,
is often matched only to a neighbouring mask. The height of the group's box (head cap
top to shoulder covers' bottom) is the same for every orientation and head yaw up to
perspective (the cap is centred on the head-yaw axis, the shoulders are body-fixed), so
a D-base whose ``meta["scale"]`` is ``"height"`` is fitted and used on r_g = h_g/h_m
(:meth:`DBase.group_scale`): on the 222 robots at 0.5-3 m of
``tools.eval_perception --seed 33 --clutter --neighbour-heads`` 98.6 % instead of 91.4 %
of the distances fall within 5 % (both D-bases calibrated the same way).

File format (versioned): ``dbase.json`` with a, b, c, R², RMSE and sample count per
mask, the digest of the M-base it belongs to and the parameters that made it.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import curve_fit

from agent.core.perception.mbase import DATA_DIR

DBASE_VERSION = 2
READABLE_VERSIONS = (1, 2)
C_BOUND = 0.1  # |c| of eq. 6 with offset (a pixel rim of up to 10 % of the mask width)
# c is only fitted when the samples span far enough: largest/smallest r_g at least this
OFFSET_SPAN = 2.5


def _model(inv_rg: np.ndarray, a: float, b: float) -> np.ndarray:
    return a * inv_rg + b


def _model_c(rg: np.ndarray, a: float, b: float, c: float) -> np.ndarray:
    return a / (rg + c) + b


@dataclass(frozen=True)
class Fit:
    """One D-base entry: eq. 6 coefficients (with the pixel-rim offset c) and the fit's quality."""

    a: float
    b: float
    r2: float
    rmse: float
    n: int
    c: float = 0.0

    def distance(self, scale: float) -> float:
        """d = a / (r_g + c) + b."""
        return self.a / (scale + self.c) + self.b


def fit_distance_model(scales: np.ndarray, distances: np.ndarray, offset: bool = True) -> Fit:
    """Fit d = a / (r_g + c) + b (eq. 6, with offset) to samples; needs >= 3 samples with
    distinct r_g. ``c`` stays 0 (the paper's eq. 6) unless ``offset`` and the samples span
    a scale ratio of at least ``OFFSET_SPAN`` and 5 samples."""
    rg = np.asarray(scales, dtype=np.float64).reshape(-1)
    d = np.asarray(distances, dtype=np.float64).reshape(-1)
    if rg.shape != d.shape:
        raise ValueError(f"scales and distances differ in length: {rg.size} vs {d.size}")
    if rg.size < 3:
        raise ValueError(f"need at least 3 samples to fit eq. 6, got {rg.size}")
    if not (np.all(np.isfinite(rg)) and np.all(np.isfinite(d))) or np.any(rg <= 0):
        raise ValueError("scales must be finite and > 0, distances finite")
    x = 1.0 / rg
    if np.ptp(x) <= 1e-9:
        raise ValueError("all scales are equal: eq. 6 is not identifiable")
    popt, _ = curve_fit(_model, x, d, p0=(0.6, 0.0))
    a, b, c = float(popt[0]), float(popt[1]), 0.0
    if offset and rg.size >= 5 and rg.max() >= OFFSET_SPAN * rg.min():
        lo = -min(C_BOUND, 0.9 * float(rg.min()))
        p3, _ = curve_fit(
            _model_c, rg, d, p0=(a, b, 0.0), bounds=([0.0, -np.inf, lo], [np.inf, np.inf, C_BOUND])
        )
        a, b, c = float(p3[0]), float(p3[1]), float(p3[2])
    res = d - _model_c(rg, a, b, c)
    ss_res = float(np.sum(res**2))
    ss_tot = float(np.sum((d - d.mean()) ** 2))
    r2 = 1.0 - ss_res / ss_tot if ss_tot > 0 else 1.0
    return Fit(a=a, b=b, r2=r2, rmse=float(np.sqrt(ss_res / d.size)), n=int(d.size), c=c)


@dataclass
class DBase:
    """Per-mask (a, b) pairs; ``fits[k]`` belongs to M-base mask k (None: not calibrated)."""

    fits: list[Fit | None]
    mbase_digest: str
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.fits or all(f is None for f in self.fits):
            raise ValueError("a D-base needs at least one fitted mask")
        good = [f for f in self.fits if f is not None]
        self._fallback = Fit(
            a=float(np.median([f.a for f in good])),
            b=float(np.median([f.b for f in good])),
            r2=float("nan"),
            rmse=float("nan"),
            n=0,
            c=float(np.median([f.c for f in good])),
        )

    def __len__(self) -> int:
        return len(self.fits)

    def coefficients(self, k: int) -> Fit:
        """The fit of mask k; a mask without its own fit gets the median (a, b, c)."""
        if not 0 <= k < len(self.fits):
            raise ValueError(f"mask index {k} outside [0, {len(self.fits)})")
        f = self.fits[k]
        return self._fallback if f is None else f

    @property
    def scale_kind(self) -> str:
        """``"height"`` (r_g = h_g/h_m) or ``"min"`` (Algorithm 1's r_g; version-1 files)."""
        kind = str(self.meta.get("scale", "min"))
        if kind not in ("height", "min"):
            raise ValueError(f"unknown D-base scale {kind!r}")
        return kind

    def group_scale(self, rg: float, box_h: float, mask_h: float) -> float:
        """The r_g this D-base is fitted on, for a group matched at Algorithm 1's ``rg``
        with box height ``box_h`` to a mask of height ``mask_h`` (px)."""
        if self.scale_kind == "min":
            return rg
        if not (box_h > 0 and mask_h > 0):
            raise ValueError(f"box and mask heights must be > 0, got {box_h}, {mask_h}")
        return box_h / mask_h

    def distance(self, k: int, scale: float) -> float:
        """Eq. 6: d = a / (r_g + c) + b with mask k's coefficients."""
        if not np.isfinite(scale) or scale <= 0:
            raise ValueError(f"scale r_g must be finite and > 0, got {scale}")
        f = self.coefficients(k)
        if scale + f.c <= 0:
            raise ValueError(f"scale r_g {scale} is below mask {k}'s model range (c = {f.c})")
        return f.distance(scale)

    def save(self, directory: Path, stem: str = "dbase") -> Path:
        directory.mkdir(parents=True, exist_ok=True)
        doc = dict(self.meta)
        doc.update(
            {
                "version": DBASE_VERSION,
                "mbase_digest": self.mbase_digest,
                "fits": [
                    None
                    if f is None
                    else {
                        "a": round(f.a, 6),
                        "b": round(f.b, 6),
                        "c": round(f.c, 6),
                        "r2": round(f.r2, 6),
                        "rmse": round(f.rmse, 6),
                        "n": f.n,
                    }
                    for f in self.fits
                ],
            }
        )
        path = directory / f"{stem}.json"
        path.write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")
        return path

    @classmethod
    def load(cls, directory: Path | None = None, stem: str = "dbase") -> DBase:
        directory = DATA_DIR if directory is None else Path(directory)
        path = directory / f"{stem}.json"
        if not path.is_file():
            raise ValueError(f"no D-base at {path}: run python -m tools.calibrate_dbase")
        doc = json.loads(path.read_text())
        if doc.get("version") not in READABLE_VERSIONS:
            raise ValueError(f"D-base version {doc.get('version')} not in {READABLE_VERSIONS}")
        fits: list[Fit | None] = [
            None
            if f is None
            else Fit(
                float(f["a"]),
                float(f["b"]),
                float(f["r2"]),
                float(f["rmse"]),
                int(f["n"]),
                float(f.get("c", 0.0)),
            )
            for f in doc["fits"]
        ]
        meta = {k: v for k, v in doc.items() if k not in ("fits", "mbase_digest")}
        return cls(fits=fits, mbase_digest=str(doc["mbase_digest"]), meta=meta)
