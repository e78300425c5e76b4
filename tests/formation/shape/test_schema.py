"""The formation file (agent/core/formation/shape/schema.py): a good file read into its tree,
and one clear ``ValueError`` naming the field for every kind of bad field."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from agent.core.formation.shape import schema
from agent.core.formation.shape.schema import MAX_SLOTS, parse_shape, shape_from_dict
from agent.core.formation.shape.spec import TREE

ROOT = Path(__file__).resolve().parents[3]

GOOD: dict[str, Any] = {
    "name": "wedge-5",
    "orient": "width",
    "slots": [
        {"parent": 0, "distance": 0.8, "angle_deg": 135},
        {"parent": 0, "distance": 0.8, "angle_deg": -135},
        {"parent": 1, "distance": 0.8, "angle_deg": 135},
        {"parent": 2, "distance": 0.8, "angle_deg": -135.0},
    ],
}


def test_a_good_file() -> None:
    shape = parse_shape(json.dumps(GOOD))
    assert (shape.name, shape.rule, shape.orient, shape.capacity) == ("wedge-5", TREE, "width", 5)
    assert shape.edges[0] == (0, 0.8, math.radians(135))
    a = 0.8 * math.sin(math.radians(45))
    np.testing.assert_allclose(
        shape.slots(5, 0.8, 0.5).positions,
        [[0, 0], [-a, -a], [a, -a], [-2 * a, -2 * a], [2 * a, -2 * a]],
        atol=1e-12,
    )
    # orient is optional, the name is trimmed; key order and spacing do not matter
    doc = {"slots": GOOD["slots"], "name": " w "}
    plain = shape_from_dict(doc)
    assert plain.orient == "depth" and plain.name == "w"
    assert parse_shape(json.dumps(GOOD, indent=4)).digest == shape.digest


def test_the_example_file_of_the_docs() -> None:
    shape = parse_shape((ROOT / "docs/examples/wedge.json").read_text())
    assert shape.capacity is not None and shape.capacity >= 6


def _with(path: str, value: Any) -> dict[str, Any]:
    """GOOD with one field set (``slots.2.parent``) or removed (value ``...``)."""
    doc = json.loads(json.dumps(GOOD))
    *head, last = path.split(".")
    node: Any = doc
    for key in head:
        node = node[int(key)] if isinstance(node, list) else node[key]
    key = int(last) if isinstance(node, list) else last
    if value is ...:
        del node[key]
    else:
        node[key] = value
    return doc


@pytest.mark.parametrize(
    ("doc", "match"),
    [
        ([1, 2], r"^shape file: expected an object"),
        (_with("colour", "red"), r"^shape file: unknown field 'colour'"),
        (_with("name", ...), r"^name: expected a non-empty string, got None"),
        (_with("name", "  "), r"^name: expected a non-empty string"),
        (_with("name", 7), r"^name: expected a non-empty string, got 7"),
        (_with("orient", "tall"), r"^orient: expected one of depth, width, got 'tall'"),
        (_with("slots", ...), r"^slots: missing"),
        (_with("slots", {}), r"^slots: expected a non-empty list"),
        (_with("slots", []), r"^slots: expected a non-empty list"),
        (_with("slots.1", 5), r"^slots\[1\]: expected an object"),
        (_with("slots.1.colour", 1), r"^slots\[1\]: unknown field 'colour'"),
        (_with("slots.1.parent", ...), r"^slots\[1\]\.parent: missing"),
        (_with("slots.1.distance", ...), r"^slots\[1\]\.distance: missing"),
        (_with("slots.1.angle_deg", ...), r"^slots\[1\]\.angle_deg: missing"),
        (_with("slots.1.parent", 1.0), r"^slots\[1\]\.parent: expected an integer slot"),
        (_with("slots.1.parent", True), r"^slots\[1\]\.parent: expected an integer slot"),
        (_with("slots.1.parent", 2), r"^slots\[1\]\.parent: 2 is not an earlier slot \(0\.\.1\)"),
        (_with("slots.3.parent", -1), r"^slots\[3\]\.parent: -1 is not an earlier slot"),
        (_with("slots.0.distance", "far"), r"^slots\[0\]\.distance: expected a number"),
        (_with("slots.0.distance", False), r"^slots\[0\]\.distance: expected a number"),
        (_with("slots.0.distance", 0), r"^slots\[0\]\.distance: expected > 0 m, got 0"),
        (_with("slots.0.distance", -0.8), r"^slots\[0\]\.distance: expected > 0 m"),
        (_with("slots.2.distance", math.inf), r"^slots\[2\]\.distance: expected a finite"),
        (_with("slots.2.angle_deg", None), r"^slots\[2\]\.angle_deg: expected a number"),
        (_with("slots.2.angle_deg", math.nan), r"^slots\[2\]\.angle_deg: expected a finite"),
    ],
)
def test_one_clear_error_per_bad_field(doc: Any, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        shape_from_dict(doc)


def test_too_many_slots(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(schema, "MAX_SLOTS", 3)
    with pytest.raises(ValueError, match=r"^slots: at most 3, got 4"):
        shape_from_dict(GOOD)
    assert MAX_SLOTS >= 10_000


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ('{"name": "x", "slots": [', r"^shape file: not JSON \(.* line 1, column 25\)"),
        ("", r"^shape file: not JSON"),
        ('{"name": "x", "slots": [{"parent": 0, "distance": 1e999, "angle_deg": 0}]}',
         r"distance: expected a finite"),
    ],
)  # fmt: skip
def test_text_errors(text: str, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        parse_shape(text)
