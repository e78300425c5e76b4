"""Foxglove's well-known message schemas, written as JSON Schema for JSON-encoded MCAP
channels (docs/design.md §10 "Seeing the fleet").

Foxglove and Lichtblick recognise a channel by its schema's *name* (``foxglove.SceneUpdate``,
``foxglove.Log``, ...) and decode JSON messages with the ``jsonschema`` schema encoding, so
a recording needs nothing but the ``mcap`` package: no protobuf, no foxglove-sdk. The
schemas here follow Foxglove's published definitions field for field (names, nesting,
enum values; descriptions left out; checked against ``@foxglove/schemas`` 2.1.0), built
from small shared parts; every field is required but those Foxglove added later, and the
builders below fill every field. ``foxglove.CompressedImage``
and ``foxglove.ImageAnnotations`` carry the camera frames agents publish with
``--publish-camera`` (tools/harness/view/scene.py).

The builders (:func:`stamp`, :func:`pose`, :func:`colour`, primitives, :func:`log`,
:func:`frame_transform`) return plain dicts ready for ``json.dumps``.
"""

from __future__ import annotations

import base64
import math
from collections.abc import Sequence
from typing import Any

JSON = dict[str, Any]

# ===================================================================== schema parts

_NUM: JSON = {"type": "number"}
_INT: JSON = {"type": "integer", "minimum": 0}
_STR: JSON = {"type": "string"}
_BOOL: JSON = {"type": "boolean"}
_NSEC: JSON = {"type": "integer", "minimum": 0, "maximum": 999_999_999}
TIME: JSON = {"type": "object", "title": "time", "properties": {"sec": _INT, "nsec": _NSEC}}
DURATION: JSON = {
    "type": "object",
    "title": "duration",
    "properties": {"sec": {"type": "integer"}, "nsec": _NSEC},
}


def _obj(title: str, props: dict[str, JSON], optional: dict[str, JSON] | None = None) -> JSON:
    """An object schema: every property of ``props`` required, those of ``optional`` not
    (the fields Foxglove added later)."""
    every = {**props, **(optional or {})}
    return {"title": title, "type": "object", "properties": every, "required": list(props)}


def _arr(items: JSON) -> JSON:
    return {"type": "array", "items": items}


def _enum(title: str, names: Sequence[str]) -> JSON:
    """An integer enum: ``oneOf`` the constants 0, 1, ... titled by ``names``."""
    return {"title": title, "oneOf": [{"title": n, "const": k} for k, n in enumerate(names)]}


VECTOR3 = _obj("foxglove.Vector3", {"x": _NUM, "y": _NUM, "z": _NUM})
POINT2 = _obj("foxglove.Point2", {"x": _NUM, "y": _NUM})
POINT3 = _obj("foxglove.Point3", {"x": _NUM, "y": _NUM, "z": _NUM})
QUATERNION = _obj("foxglove.Quaternion", {"x": _NUM, "y": _NUM, "z": _NUM, "w": _NUM})
POSE = _obj("foxglove.Pose", {"position": VECTOR3, "orientation": QUATERNION})
COLOR = _obj("foxglove.Color", {"r": _NUM, "g": _NUM, "b": _NUM, "a": _NUM})
KEY_VALUE = _obj("foxglove.KeyValuePair", {"key": _STR, "value": _STR})
_INDICES = _arr({"type": "integer", "minimum": 0})

ARROW = _obj(
    "foxglove.ArrowPrimitive",
    {
        "pose": POSE,
        "shaft_length": _NUM,
        "shaft_diameter": _NUM,
        "head_length": _NUM,
        "head_diameter": _NUM,
        "color": COLOR,
    },
)
CUBE = _obj("foxglove.CubePrimitive", {"pose": POSE, "size": VECTOR3, "color": COLOR})
SPHERE = _obj("foxglove.SpherePrimitive", {"pose": POSE, "size": VECTOR3, "color": COLOR})
CYLINDER = _obj(
    "foxglove.CylinderPrimitive",
    {"pose": POSE, "size": VECTOR3, "bottom_scale": _NUM, "top_scale": _NUM, "color": COLOR},
)
LINE_TYPES = ("LINE_STRIP", "LINE_LOOP", "LINE_LIST")
LINE = _obj(
    "foxglove.LinePrimitive",
    {
        "type": _enum("foxglove.LineType", LINE_TYPES),
        "pose": POSE,
        "thickness": _NUM,
        "scale_invariant": _BOOL,
        "points": _arr(POINT3),
        "color": COLOR,
        "colors": _arr(COLOR),
        "indices": _INDICES,
    },
)
TRIANGLES = _obj(
    "foxglove.TriangleListPrimitive",
    {
        "pose": POSE,
        "points": _arr(POINT3),
        "color": COLOR,
        "colors": _arr(COLOR),
        "indices": _INDICES,
    },
)
TEXT = _obj(
    "foxglove.TextPrimitive",
    {
        "pose": POSE,
        "billboard": _BOOL,
        "font_size": _NUM,
        "scale_invariant": _BOOL,
        "color": COLOR,
        "text": _STR,
    },
)
_BYTES: JSON = {"type": "string", "contentEncoding": "base64"}
MODEL = _obj(
    "foxglove.ModelPrimitive",
    {
        "pose": POSE,
        "scale": VECTOR3,
        "color": COLOR,
        "override_color": _BOOL,
        "url": _STR,
        "media_type": _STR,
        "data": _BYTES,
    },
)
#: The primitive lists of a scene entity, in Foxglove's order.
PRIMITIVES = {
    "arrows": ARROW,
    "cubes": CUBE,
    "spheres": SPHERE,
    "cylinders": CYLINDER,
    "lines": LINE,
    "triangles": TRIANGLES,
    "texts": TEXT,
    "models": MODEL,
}
ENTITY = _obj(
    "foxglove.SceneEntity",
    {
        "timestamp": TIME,
        "frame_id": _STR,
        "id": _STR,
        "lifetime": DURATION,
        "frame_locked": _BOOL,
        "metadata": _arr(KEY_VALUE),
        **{name: _arr(s) for name, s in PRIMITIVES.items()},
    },
)
DELETION = _obj(
    "foxglove.SceneEntityDeletion",
    {
        "timestamp": TIME,
        "type": _enum("foxglove.SceneEntityDeletionType", ("MATCHING_ID", "ALL")),
        "id": _STR,
    },
)
SCENE_UPDATE = _obj("foxglove.SceneUpdate", {"deletions": _arr(DELETION), "entities": _arr(ENTITY)})

LOG_LEVELS = ("UNKNOWN", "DEBUG", "INFO", "WARNING", "ERROR", "FATAL")
DEBUG, INFO, WARNING, ERROR = 1, 2, 3, 4
LOG = _obj(
    "foxglove.Log",
    {
        "timestamp": TIME,
        "level": _enum("foxglove.LogLevel", LOG_LEVELS),
        "message": _STR,
        "name": _STR,
        "file": _STR,
        "line": _INT,
    },
)
FRAME_TRANSFORM = _obj(
    "foxglove.FrameTransform",
    {
        "timestamp": TIME,
        "parent_frame_id": _STR,
        "child_frame_id": _STR,
        "translation": VECTOR3,
        "rotation": QUATERNION,
    },
)
COMPRESSED_IMAGE = _obj(
    "foxglove.CompressedImage",
    {"timestamp": TIME, "frame_id": _STR, "data": _BYTES, "format": _STR},
)
CIRCLE_ANNOTATION = _obj(
    "foxglove.CircleAnnotation",
    {
        "timestamp": TIME,
        "position": POINT2,
        "diameter": _NUM,
        "thickness": _NUM,
        "fill_color": COLOR,
        "outline_color": COLOR,
    },
    {"metadata": _arr(KEY_VALUE)},
)
POINTS_TYPES = ("UNKNOWN", "POINTS", "LINE_LOOP", "LINE_STRIP", "LINE_LIST")
POINTS_ANNOTATION = _obj(
    "foxglove.PointsAnnotation",
    {
        "timestamp": TIME,
        "type": _enum("foxglove.PointsAnnotationType", POINTS_TYPES),
        "points": _arr(POINT2),
        "outline_color": COLOR,
        "outline_colors": _arr(COLOR),
        "fill_color": COLOR,
        "thickness": _NUM,
    },
    {"metadata": _arr(KEY_VALUE)},
)
TEXT_ANNOTATION = _obj(
    "foxglove.TextAnnotation",
    {
        "timestamp": TIME,
        "position": POINT2,
        "text": _STR,
        "font_size": _NUM,
        "text_color": COLOR,
        "background_color": COLOR,
    },
    {"metadata": _arr(KEY_VALUE)},
)
IMAGE_ANNOTATIONS = _obj(
    "foxglove.ImageAnnotations",
    {
        "circles": _arr(CIRCLE_ANNOTATION),
        "points": _arr(POINTS_ANNOTATION),
        "texts": _arr(TEXT_ANNOTATION),
    },
    {"timestamp": TIME, "metadata": _arr(KEY_VALUE)},
)

#: Every well-known schema this module defines, by its Foxglove name.
SCHEMAS: dict[str, JSON] = {
    s["title"]: s for s in (SCENE_UPDATE, LOG, FRAME_TRANSFORM, COMPRESSED_IMAGE, IMAGE_ANNOTATIONS)
}

# ===================================================================== message builders


def stamp(t_ns: int) -> JSON:
    """A Foxglove ``time`` from nanoseconds (>= 0)."""
    sec, nsec = divmod(max(0, int(t_ns)), 1_000_000_000)
    return {"sec": sec, "nsec": nsec}


def vec(x: float, y: float, z: float = 0.0) -> JSON:
    return {"x": round(float(x), 4), "y": round(float(y), 4), "z": round(float(z), 4)}


def yaw(h: float) -> JSON:
    """The quaternion of a turn by ``h`` rad about +z."""
    return {"x": 0.0, "y": 0.0, "z": math.sin(h / 2.0), "w": math.cos(h / 2.0)}


def pose(x: float, y: float, z: float = 0.0, h: float = 0.0) -> JSON:
    return {"position": vec(x, y, z), "orientation": yaw(h)}


def colour(rgb: Sequence[float], a: float = 1.0) -> JSON:
    r, g, b = (float(c) for c in rgb[:3])
    return {"r": r, "g": g, "b": b, "a": float(a)}


def cylinder(p: JSON, diameter: float, height: float, c: JSON) -> JSON:
    return {
        "pose": p,
        "size": vec(diameter, diameter, height),
        "bottom_scale": 1.0,
        "top_scale": 1.0,
        "color": c,
    }


def arrow(p: JSON, length: float, c: JSON) -> JSON:
    """An arrow from ``p`` along its +x, ``length`` long in all."""
    head = 0.3 * length
    return {
        "pose": p,
        "shaft_length": length - head,
        "shaft_diameter": 0.04,
        "head_length": head,
        "head_diameter": 0.09,
        "color": c,
    }


def line(points: Sequence[Sequence[float]], c: JSON, thickness: float, kind: str) -> JSON:
    """A line through ``points`` ((x, y) or (x, y, z)); ``kind`` one of :data:`LINE_TYPES`."""
    return {
        "type": LINE_TYPES.index(kind),
        "pose": pose(0.0, 0.0),
        "thickness": thickness,
        "scale_invariant": False,
        "points": [vec(*p) for p in points],
        "color": c,
        "colors": [],
        "indices": [],
    }


def text(p: JSON, words: str, c: JSON, size: float = 0.12) -> JSON:
    """A label facing the camera, ``size`` m high."""
    return {
        "pose": p,
        "billboard": True,
        "font_size": size,
        "scale_invariant": False,
        "color": c,
        "text": words,
    }


def entity(t_ns: int, ident: str, frame: str = "world", **primitives: list[JSON]) -> JSON:
    """A scene entity ``ident`` in ``frame`` that stays until replaced (lifetime 0);
    ``primitives``: lists named as in :data:`PRIMITIVES`, the others empty."""
    unknown = set(primitives) - set(PRIMITIVES)
    if unknown:
        raise ValueError(f"no primitive list {sorted(unknown)} in a scene entity")
    return {
        "timestamp": stamp(t_ns),
        "frame_id": frame,
        "id": ident,
        "lifetime": {"sec": 0, "nsec": 0},
        "frame_locked": False,
        "metadata": [],
        **{name: primitives.get(name, []) for name in PRIMITIVES},
    }


def scene_update(entities: list[JSON], clear_at: int | None = None) -> JSON:
    """A ``SceneUpdate`` of ``entities``; ``clear_at`` (world time, ns): first delete every
    entity of the topic (a deletion of type ``ALL``, which a viewer applies before the
    entities), so that the update replaces the topic's whole drawing."""
    gone = [] if clear_at is None else [{"timestamp": stamp(clear_at), "type": 1, "id": ""}]
    return {"deletions": gone, "entities": entities}


def log(t_ns: int, level: int, name: str, message: str) -> JSON:
    if not 0 <= level < len(LOG_LEVELS):
        raise ValueError(f"log level {level} is not one of 0..{len(LOG_LEVELS) - 1}")
    return {
        "timestamp": stamp(t_ns),
        "level": level,
        "message": message,
        "name": name,
        "file": "",
        "line": 0,
    }


def frame_transform(t_ns: int, parent: str, child: str, x: float, y: float, h: float) -> JSON:
    """``child`` placed in ``parent``: a point p of ``child`` is R(h)·p + (x, y) in ``parent``."""
    return {
        "timestamp": stamp(t_ns),
        "parent_frame_id": parent,
        "child_frame_id": child,
        "translation": vec(x, y),
        "rotation": yaw(h),
    }


def compressed_image(t_ns: int, frame_id: str, data: bytes, fmt: str = "jpeg") -> JSON:
    """A ``foxglove.CompressedImage``: ``data`` encoded as ``fmt`` (jpeg, png, ...)."""
    return {
        "timestamp": stamp(t_ns),
        "frame_id": frame_id,
        "data": base64.b64encode(data).decode("ascii"),
        "format": fmt,
    }


def point2(x: float, y: float) -> JSON:
    return {"x": round(float(x), 2), "y": round(float(y), 2)}


def box_annotation(t_ns: int, x: float, y: float, w: float, h: float, c: JSON) -> JSON:
    """A rectangle of image pixels (x, y from the top left, w x h) as a closed line."""
    corners = [point2(x, y), point2(x + w, y), point2(x + w, y + h), point2(x, y + h)]
    return {
        "timestamp": stamp(t_ns),
        "type": POINTS_TYPES.index("LINE_LOOP"),
        "points": corners,
        "outline_color": c,
        "outline_colors": [],
        "fill_color": colour((0.0, 0.0, 0.0), 0.0),
        "thickness": 1.0,
    }


def text_annotation(t_ns: int, x: float, y: float, words: str, c: JSON, size: float = 8.0) -> JSON:
    """Text at image pixel (x, y), ``size`` pixels high, on a dark translucent ground."""
    return {
        "timestamp": stamp(t_ns),
        "position": point2(x, y),
        "text": words,
        "font_size": float(size),
        "text_color": c,
        "background_color": colour((0.0, 0.0, 0.0), 0.5),
    }


def image_annotations(points: list[JSON], texts: list[JSON]) -> JSON:
    return {"circles": [], "points": points, "texts": texts}
