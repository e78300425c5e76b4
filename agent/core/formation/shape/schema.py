"""The formation file: a shape's slots as a tree, in JSON, checked field by field (the
format is in docs/formation.md "Shapes"; the tree's conventions in :mod:`tree`).

    {
      "name": "wedge-5",
      "orient": "width",
      "slots": [
        {"parent": 0, "distance": 0.8, "angle_deg": 135},
        {"parent": 0, "distance": 0.8, "angle_deg": -135},
        {"parent": 1, "distance": 0.8, "angle_deg": 135},
        {"parent": 2, "distance": 0.8, "angle_deg": -135}
      ]
    }

Slot 0 is the leader and is not listed; ``slots[i]`` is slot i + 1, whose ``parent`` is an
earlier slot (0 .. i). ``distance`` is in metres, ``angle_deg`` in degrees counter-clockwise
from the parent's facing (0 ahead, 90 left, 180 behind, −90 right). ``orient``
(optional, default ``depth``): which of the shape's axes the fleet's principal axis
becomes (:mod:`builtin`). A bad field raises one ``ValueError`` naming it, e.g.
``slots[2].parent: 5 is not an earlier slot (0..2)``. Reading the file is the caller's
(the core does no I/O); :func:`parse_shape` takes its text.
"""

from __future__ import annotations

import json
import math
from typing import Any

from agent.core.formation.shape.spec import ORIENTS, TREE, Shape

#: The most slots a formation file may define.
MAX_SLOTS = 100_000

_TOP = ("name", "orient", "slots")
_SLOT = ("parent", "distance", "angle_deg")


def _number(v: Any, where: str) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise ValueError(f"{where}: expected a number, got {v!r}")
    x = float(v)
    if not math.isfinite(x):
        raise ValueError(f"{where}: expected a finite number, got {v!r}")
    return x


def _unknown(doc: dict[str, Any], known: tuple[str, ...], where: str) -> None:
    extra = sorted(str(k) for k in doc if k not in known)
    if extra:
        raise ValueError(f"{where}unknown field {extra[0]!r} (fields: {', '.join(known)})")


def _slot(k: int, item: Any) -> tuple[int, float, float]:
    where = f"slots[{k}]"
    if not isinstance(item, dict):
        raise ValueError(f"{where}: expected an object with {', '.join(_SLOT)}")
    _unknown(item, _SLOT, f"{where}: ")
    for key in _SLOT:
        if key not in item:
            raise ValueError(f"{where}.{key}: missing")
    parent = item["parent"]
    if isinstance(parent, bool) or not isinstance(parent, int):
        raise ValueError(f"{where}.parent: expected an integer slot, got {parent!r}")
    if not 0 <= parent <= k:
        raise ValueError(f"{where}.parent: {parent} is not an earlier slot (0..{k})")
    distance = _number(item["distance"], f"{where}.distance")
    if distance <= 0.0:
        raise ValueError(f"{where}.distance: expected > 0 m, got {item['distance']!r}")
    angle = _number(item["angle_deg"], f"{where}.angle_deg")
    return parent, distance, math.radians(angle)


def shape_from_dict(doc: Any) -> Shape:
    """The shape a formation file's parsed document defines (JSON, or YAML read by the
    caller: module doc); ``ValueError`` naming the first bad field."""
    if not isinstance(doc, dict):
        raise ValueError("shape file: expected an object (a mapping) with name and slots")
    _unknown(doc, _TOP, "shape file: ")
    name = doc.get("name")
    if not isinstance(name, str) or not name.strip():
        raise ValueError(f"name: expected a non-empty string, got {name!r}")
    orient = doc.get("orient", "depth")
    if orient not in ORIENTS:
        raise ValueError(f"orient: expected one of {', '.join(ORIENTS)}, got {orient!r}")
    if "slots" not in doc:
        raise ValueError("slots: missing")
    slots = doc["slots"]
    if not isinstance(slots, list) or not slots:
        raise ValueError("slots: expected a non-empty list (the leader's children and theirs)")
    if len(slots) > MAX_SLOTS:
        raise ValueError(f"slots: at most {MAX_SLOTS}, got {len(slots)}")
    edges = tuple(_slot(k, item) for k, item in enumerate(slots))
    return Shape(name.strip(), TREE, edges, orient)


def parse_shape(text: str) -> Shape:
    """The shape of a formation file's text (JSON; ``ValueError`` for a syntax error, with
    its line and column, or a bad field)."""
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(
            f"shape file: not JSON ({exc.msg} at line {exc.lineno}, column {exc.colno})"
        ) from exc
    return shape_from_dict(doc)
