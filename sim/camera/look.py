"""What the simulated world looks like: a look, parsed from ``--look SPEC`` (docs/world.md
"Looks"; docs/design.md §4).

A real NAO's pictures differ from the simulated default in ways the detector of the NAO
paper 3.1 (an HSV threshold on the caps' and shoulders' orange) and the visual compass
of 3.2.1 are sensitive to: the plastic's orange, the room's light level and colour
temperature, sensor noise, motion blur while the head turns and the camera's auto
exposure. A :class:`Look` names those parameters; :mod:`sim.camera.picture` applies the
picture's part of them and :mod:`sim.physics.world` recolours the NAO model's orange parts.

``SPEC`` is a comma list, each item a ``KEY:VALUE`` or the name of a preset (a preset's
values, later items overriding them):

- ``hue:DEG`` shift of the orange parts' hue, degrees in [-180, 180];
- ``sat:F`` their saturation times F, in [0, 1];
- ``light:F`` the light level: every pixel times F, in [0.05, 4];
- ``warm:F`` colour temperature, in [-1, 1]: red times (1 + 0.3 F), blue times
  (1 - 0.3 F) (> 0 a warm, tungsten-like light; < 0 a cold one);
- ``noise:SIGMA`` Gaussian sensor noise, σ in grey levels, in [0, 64];
- ``blur:PX`` motion blur: a picture taken after the head turned is smeared over PX
  pixels along the image rows (whole pixels, [0, 64]);
- ``exposure:off|auto|TARGET`` auto exposure: the picture scaled so that its mean
  brightness approaches TARGET grey levels ([16, 240]; ``auto``: :data:`AE_TARGET`);
- ``seed:N`` the noise's seed (an int in [0, 2**32)), mixed with the scenario's.

``default`` (or an empty SPEC) is the world as it always was: :func:`Look.is_default`,
and the pictures are the same bit for bit.
"""

from __future__ import annotations

import argparse
import colorsys
import math
from dataclasses import dataclass, fields, replace
from typing import Any

#: Auto exposure's target mean brightness (grey levels of 255) for ``exposure:auto``:
#: about the mean of the default look's pictures of a generated room (≈ 100).
AE_TARGET = 100.0
#: How the warm/cold tint moves red and blue per unit of ``warm``.
WARM_GAIN = 0.3

# (low, high) of each numeric field.
RANGES: dict[str, tuple[float, float]] = {
    "hue": (-180.0, 180.0),
    "sat": (0.0, 1.0),
    "light": (0.05, 4.0),
    "warm": (-1.0, 1.0),
    "noise": (0.0, 64.0),
    "blur": (0.0, 64.0),
    "exposure": (16.0, 240.0),
    "seed": (0.0, 2.0**32 - 1),
}
INTEGER_FIELDS = ("blur", "seed")


@dataclass(frozen=True)
class Look:
    """One look of the world (module docstring). ``exposure`` None: auto exposure off."""

    hue: float = 0.0
    sat: float = 1.0
    light: float = 1.0
    warm: float = 0.0
    noise: float = 0.0
    blur: int = 0
    exposure: float | None = None
    seed: int = 0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "exposure" and value is None:
                continue
            _check(f.name, value)

    @classmethod
    def parse(cls, text: str) -> Look:
        """The look of ``SPEC`` (module docstring); ``ValueError`` naming the bad item."""
        look = cls()
        seen: set[str] = set()
        for raw in str(text).split(","):
            item = raw.strip()
            if not item:
                continue
            key, sep, value = item.partition(":")
            key = key.strip().lower()
            if not sep:
                if key not in PRESETS:
                    raise ValueError(
                        f"look item {item!r}: neither KEY:VALUE nor a preset "
                        f"({', '.join(sorted(PRESETS))})"
                    )
                look = replace(look, **_changed(PRESETS[key]))
                continue
            if key not in RANGES:
                raise ValueError(f"look item {item!r}: unknown key {key!r} ({', '.join(RANGES)})")
            if key in seen:
                raise ValueError(f"look item {item!r}: {key} given twice")
            seen.add(key)
            kw: dict[str, Any] = {key: _value(key, value.strip())}
            look = replace(look, **kw)
        return look

    def is_default(self) -> bool:
        """True when the look changes nothing (the pictures are today's bit for bit)."""
        return self == Look()

    def recolours(self) -> bool:
        """True when the NAO model's orange parts change colour."""
        return self.hue != 0.0 or self.sat != 1.0

    def develops(self) -> bool:
        """True when :func:`sim.camera.picture.develop` changes a picture."""
        return (
            self.light != 1.0
            or self.warm != 0.0
            or self.noise > 0
            or self.blur > 0
            or (self.exposure is not None)
        )

    def recolour(
        self, rgba: tuple[float, float, float, float]
    ) -> tuple[float, float, float, float]:
        """``rgba`` (the NAO model's orange) with its hue turned by ``hue`` degrees and its
        saturation times ``sat``; the very tuple when the look does not recolour."""
        if not self.recolours():
            return rgba
        h, s, v = colorsys.rgb_to_hsv(*rgba[:3])
        r, g, b = colorsys.hsv_to_rgb((h + self.hue / 360.0) % 1.0, s * self.sat, v)
        return (r, g, b, rgba[3])

    def __str__(self) -> str:
        """The SPEC of this look (``default`` if it changes nothing); parses back to it."""
        items = []
        for key, value in _changed(self).items():
            if key == "exposure":
                items.append("exposure:auto" if value == AE_TARGET else f"exposure:{value!r}")
            else:
                items.append(f"{key}:{value!r}")
        return ",".join(items) or "default"


def _changed(look: Look) -> dict[str, Any]:
    """The fields of ``look`` that differ from the default look, in field order."""
    base = Look()
    return {
        f.name: getattr(look, f.name)
        for f in fields(look)
        if getattr(look, f.name) != getattr(base, f.name)
    }


def _value(key: str, text: str) -> float | int | None:
    """The value of ``key:text``, checked; ``ValueError`` with the reason."""
    if key == "exposure":
        if text.lower() == "off":
            return None
        if text.lower() == "auto":
            return AE_TARGET
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"look {key}:{text}: {text!r} is not a number") from None
    if key in INTEGER_FIELDS:
        if not (math.isfinite(value) and value == int(value)):
            raise ValueError(f"look {key}:{text}: must be a whole number")
        out: float | int = int(value)
    else:
        out = value
    _check(key, out)
    return out


def _check(key: str, value: object) -> None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"look {key}: {value!r} is not a number")
    if key in INTEGER_FIELDS and not isinstance(value, int):
        raise ValueError(f"look {key}: {value!r} must be a whole number")
    lo, hi = RANGES[key]
    if not (math.isfinite(value) and lo <= value <= hi):
        raise ValueError(f"look {key}:{value!r} outside [{lo:g}, {hi:g}]")


#: Named looks (usable as items of a SPEC).
PRESETS: dict[str, Look] = {
    "default": Look(),
    # a dim room under warm lamps, the camera's auto exposure making up for it
    "dim-warm": Look(light=0.45, warm=0.6, noise=3.0, exposure=AE_TARGET),
    # caps and shoulders of another colour: the default detector no longer sees NAOs
    "teal-caps": Look(hue=167.0, sat=0.8),
    # a cheap sensor: noise, and smear when the head has just turned
    "noisy": Look(noise=8.0, blur=6),
}

HELP = (
    "what the world looks like: default, a preset ("
    + ", ".join(p for p in PRESETS if p != "default")
    + ") or KEY:VALUE items, comma separated: hue:DEG, sat:F, light:F, warm:F, noise:SIGMA, "
    "blur:PX, exposure:off|auto|TARGET, seed:N (docs/world.md, Looks)"
)


def look_arg(text: str) -> Look:
    """``--look SPEC`` as an argparse type: the look; a bad SPEC a usage error saying why."""
    try:
        return Look.parse(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
