"""A calibration of the recogniser: its M-base (NAO paper 3.1.2), its D-base (eq. 6, 5.2.1,
Table 1) and its orange range (3.1.1), as one folder with one digest.

The built-in calibration is the packaged M-base and D-base (``agent/core/perception/data``,
rendered from the simulated NAOs) with the paper's orange range. A lab builds its own
from its robots' camera images with ``python -m tools.calibrate`` and hands the folder
to its agents (``python -m agent --calibration DIR``). The folder holds:

- ``mbase.npz``, ``mbase.json``: the M-base (:mod:`agent.core.perception.mbase`'s format);
- ``dbase.json``: the D-base of that M-base (:mod:`agent.core.perception.dbase`'s format);
- ``orange.json``: ``{"hsv_low": [H, S, V], "hsv_high": [H, S, V]}``
  (:class:`~agent.core.perception.segmentation.OrangeRange`);
- ``calibration.json``: the manifest, ``{"version": 1, "digest": ..., "camera": {...}}``
  plus how it was made (the capture's robots, plan, the build's figures).

The digest is the SHA-256 of a canonical JSON of the M-base's content digest, the
D-base's coefficients (as saved: 6 decimals) and scale, and the orange range: equal
content, equal digest, whatever the file bytes. An agent reports it in its status and
record, so a fleet sees which calibration each robot used. A folder is checked file by
file; every bad file gets one line saying what is wrong with it.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from agent.core.perception.camera import CameraModel
from agent.core.perception.dbase import DBase
from agent.core.perception.mbase import MBase
from agent.core.perception.segmentation import ORANGE, OrangeRange

CALIBRATION_VERSION = 1
MANIFEST = "calibration.json"
ORANGE_FILE = "orange.json"
FILES = ("mbase.npz", "mbase.json", "dbase.json", ORANGE_FILE, MANIFEST)
BUILTIN = "built-in"


class CalibrationError(ValueError):
    """A calibration folder that cannot be used; the text has one line per bad file."""


def camera_params(camera: CameraModel) -> dict[str, float | int]:
    """The camera numbers a calibration depends on (in its manifest, checked on load)."""
    return {
        "width": camera.width,
        "height": camera.height,
        "hfov_deg": round(math.degrees(camera.hfov), 6),
        "vfov_deg": round(math.degrees(camera.vfov), 6),
        "height_m": round(camera.height_m, 6),
        "pitch_deg": round(math.degrees(camera.pitch), 6),
        "cam_forward_m": round(camera.cam_forward, 6),
    }


def digest_of(mbase: MBase, dbase: DBase, orange: OrangeRange) -> str:
    """The calibration's content digest (module docstring)."""
    fits = [
        None if f is None else [round(f.a, 6), round(f.b, 6), round(f.c, 6), int(f.n > 0)]
        for f in dbase.fits
    ]
    doc = {
        "mbase": mbase.digest(),
        "dbase": {"scale": dbase.scale_kind, "mbase": dbase.mbase_digest, "fits": fits},
        "orange": orange.to_dict(),
    }
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()


@dataclass(frozen=True)
class Calibration:
    """M-base, D-base and orange range that belong together; ``source`` is the folder
    (or ``"built-in"``) and ``meta`` the manifest."""

    mbase: MBase
    dbase: DBase
    orange: OrangeRange = ORANGE
    source: str = BUILTIN
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        check_pair(self.mbase, self.dbase)

    @property
    def digest(self) -> str:
        return digest_of(self.mbase, self.dbase, self.orange)

    def save(self, directory: Path, meta: dict[str, Any] | None = None) -> str:
        """Write the folder (the five files); returns the digest."""
        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        self.mbase.save(directory)
        self.dbase.save(directory)
        (directory / ORANGE_FILE).write_text(json.dumps(self.orange.to_dict(), indent=1) + "\n")
        doc = dict(meta if meta is not None else self.meta)
        doc.setdefault("camera", camera_params(CameraModel()))
        doc.update({"version": CALIBRATION_VERSION, "digest": self.digest})
        (directory / MANIFEST).write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")
        return self.digest


def check_pair(mbase: MBase, dbase: DBase) -> None:
    """The D-base must have been calibrated for this M-base (``ValueError``)."""
    if len(dbase) != len(mbase):
        raise ValueError(f"the D-base has {len(dbase)} entries, the M-base {len(mbase)} masks")
    if dbase.mbase_digest != mbase.digest():
        raise ValueError("the D-base was calibrated for another M-base (digest mismatch)")


def builtin() -> Calibration:
    """The packaged calibration (rendered M-base and D-base, the paper's orange)."""
    return Calibration(MBase.load(), DBase.load(), ORANGE)


def _json(path: Path) -> Any:
    try:
        return json.loads(path.read_text())
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"unreadable: {exc}") from None
    except json.JSONDecodeError as exc:
        raise ValueError(f"not JSON: {exc}") from None


def _check_fits(db: DBase) -> None:
    for k, f in enumerate(db.fits):
        if f is None:
            continue
        if not all(math.isfinite(v) for v in (f.a, f.b, f.c)) or f.a <= 0 or f.n < 0:
            raise ValueError(f"mask {k}: eq. 6 needs finite a > 0, b and c, got {f}")
    _ = db.scale_kind  # raises on an unknown scale


def load(directory: str | Path) -> Calibration:
    """The calibration in ``directory``; :class:`CalibrationError` lists every bad file."""
    d = Path(directory)
    if not d.is_dir():
        raise CalibrationError(f"calibration folder {d}: not a directory")
    problems: dict[str, str] = {}
    for name in FILES:
        if not (d / name).is_file():
            problems[name] = "missing"
    orange: OrangeRange | None = None
    if ORANGE_FILE not in problems:
        try:
            orange = OrangeRange.from_dict(_json(d / ORANGE_FILE))
        except ValueError as exc:
            problems[ORANGE_FILE] = str(exc)
    mbase: MBase | None = None
    if "mbase.json" not in problems:
        try:
            _json(d / "mbase.json")
        except ValueError as exc:
            problems["mbase.json"] = str(exc)
    if not {"mbase.npz", "mbase.json"} & set(problems):
        try:
            mbase = MBase.load(d)
        except Exception as exc:  # a damaged archive: zipfile, numpy and key errors too
            problems["mbase.npz"] = f"{type(exc).__name__}: {exc}"
    dbase: DBase | None = None
    if "dbase.json" not in problems:
        try:
            _json(d / "dbase.json")
            dbase = DBase.load(d)
            _check_fits(dbase)
            if mbase is not None:
                check_pair(mbase, dbase)
        except (ValueError, KeyError, TypeError, IndexError) as exc:
            why = f"no field {exc}" if isinstance(exc, KeyError) else str(exc)
            problems["dbase.json"] = why
            dbase = None
    meta: dict[str, Any] = {}
    if MANIFEST not in problems:
        try:
            doc = _json(d / MANIFEST)
            if not isinstance(doc, dict):
                raise ValueError("expected a JSON object")
            meta = doc
            if doc.get("version") != CALIBRATION_VERSION:
                raise ValueError(f"version {doc.get('version')!r}, expected {CALIBRATION_VERSION}")
            cam = doc.get("camera")
            want = camera_params(CameraModel())
            if cam is not None and cam != want:
                raise ValueError(
                    f"made for the camera {cam}, the agent's camera model is {want} "
                    "(agent/core/nao.py)"
                )
            if mbase is not None and dbase is not None and orange is not None:
                got = digest_of(mbase, dbase, orange)
                if doc.get("digest") != got:
                    raise ValueError(
                        f"digest {str(doc.get('digest'))[:16]}... does not match the folder's "
                        f"content ({got[:16]}...): a file was changed after the build"
                    )
        except ValueError as exc:
            problems[MANIFEST] = str(exc)
    if problems:
        lines = [f"  {d / name}: {why}" for name, why in sorted(problems.items())]
        raise CalibrationError(f"calibration folder {d} is not usable:\n" + "\n".join(lines))
    assert mbase is not None and dbase is not None and orange is not None
    return Calibration(mbase, dbase, orange, str(d), meta)
