"""Labelled views for measuring the perception of the NAO paper, section 3, in the
simulated world: the scenes of ``python -m tools.eval_perception``.

Each view: an observer with a random pose and head yaw across ±119.5°, 1-3 other NAOs at
0.4 m to ``max_distance`` + 0.15 m with any orientation in its field of view (unused
robots parked in a corner), optionally orange lookalike clutter in the room, the
neighbours' heads straight or mid-sweep; the observer's picture, and a :class:`Truth` for
every other robot. Seeded (``numpy.random.Generator``), ten views per world.

Labels. A robot counts for recall when its distance is in [0.5, max] m, it is wholly in
the image, no other robot overlaps it in the image and no clutter cube nearer than it
does (angular extent ±atan(0.15/d), orange band 0.34-0.62 m high). Robots with a clutter
cube *behind* them overlapping them in the image (their orange blobs may merge) count,
and are reported apart too; so are those left out because a robot behind overlaps them
(the placement avoids overlapping robots, so they are few).

Overlap (``--overlap``, the paper's first cause of failure, section 6): every view puts a
second NAO partly *behind* a first one in the image (20-90 % of its angular extent
covered, 0.45-1.2 m further away), plus sometimes a free third one. Occlusion is then
measured, not guessed: each robot is also rendered alone, and its *visible orange
fraction* is the share of its own orange pixels still seen in the full view and not
covered by a nearer robot's orange. A robot counts when it is in range, wholly in the
image and at least ``VISIBLE_MIN`` (80 %) of its orange is visible; the front robots
(whose blobs merge with those of the robot behind) and the partly hidden back robots are
reported apart, with the recall per visible fraction.
"""

from __future__ import annotations

import math
from collections.abc import Generator
from dataclasses import dataclass

import numpy as np

from agent.core.perception import SIGHT_MAX, SIGHT_MIN
from agent.core.perception.camera import CameraModel
from sim.camera.look import Look
from sim.physics.world import World
from sim.scenarios import ClutterSpec, RobotSpec, Scenario

YAW_LIMIT = math.radians(119.5)
HALF_WIDTH = 0.15  # m: half the shoulder width of a NAO plus a margin
RANGE = (SIGHT_MIN, SIGHT_MAX)
VISIBLE_MIN = 0.8  # overlap: share of a robot's orange that must be visible to count
BAND = (0.34, 0.62)  # m: heights of the orange parts (shoulder covers to head cap) + margin
VIEWS_PER_WORLD = 10


@dataclass
class Truth:
    robot: int
    distance: float
    bearing: float  # observer body frame, rad
    cam_bearing: float  # from the optical centre, relative to the camera axis
    half_angle: float
    in_view: bool = True
    occluded: bool = False
    overlapped: bool = False  # a robot behind it overlaps it in the image
    cluttered: bool = False  # a clutter cube behind it overlaps it in the image
    max_distance: float = RANGE[1]
    visible: float | None = None  # --overlap: visible orange fraction (rendered)
    role: str = ""  # --overlap: "front" (a robot behind it), "back" (partly hidden) or ""
    clutter_occluded: bool = False  # a clutter cube nearer than it overlaps it

    @property
    def in_range(self) -> bool:
        if not (RANGE[0] <= self.distance <= self.max_distance and self.in_view):
            return False
        if self.visible is not None:  # measured occlusion replaces the geometric guess
            return self.visible >= VISIBLE_MIN and not self.clutter_occluded
        return not self.occluded

    @property
    def counts(self) -> bool:
        return self.in_range and (self.visible is not None or not self.overlapped)


@dataclass
class Scene:
    """One labelled view: the observer's picture at head yaw ``yaw`` and the labels of
    every other robot of the world (the parked ones too, for precision)."""

    image: np.ndarray
    yaw: float
    truths: list[Truth]


def wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def room_for(max_distance: float) -> float:
    """Room half-size: 4 m, or enough for robots ``max_distance`` away from the observer."""
    return max(4.0, round(max_distance + 1.9, 1))


def make_world(
    rng: np.random.Generator,
    n_robots: int,
    clutter: bool,
    seed: int,
    room: float = 4.0,
    renderer: str = "tiny",
    look: Look | None = None,
) -> World:
    robots = tuple(RobotSpec(i + 1, -3.0 + 0.7 * i, -3.0, math.pi / 2) for i in range(n_robots + 1))
    items: list[ClutterSpec] = []
    if clutter:
        # orange cubes scattered in the middle of the room, where the views look (as many
        # per square metre in a larger room)
        spread = room - 1.6
        dens = (spread / 2.4) ** 2
        for _ in range(int(rng.integers(round(6 * dens), round(12 * dens)))):
            size = float(rng.uniform(0.03, 0.09))
            x, y = (float(v) for v in rng.uniform(-spread, spread, size=2))
            z = float(rng.uniform(size / 2, 0.75))
            items.append(ClutterSpec(round(x, 3), round(y, 3), round(z, 3), round(size, 3)))
    sc = Scenario(robots=robots, clutter=tuple(items), seed=seed, room=room, look=look or Look())
    return World(sc, noise=False, renderer=renderer)


def place(
    w: World,
    rng: np.random.Generator,
    cam: CameraModel,
    n_others: int,
    clutter: tuple[ClutterSpec, ...],
    max_distance: float = RANGE[1],
    overlap: bool = False,
) -> tuple[float, list[Truth]]:
    """Random observer pose, head yaw and neighbours; returns the head yaw and the labels.

    With ``overlap`` the second neighbour stands 0.45-1.2 m behind the first, shifted
    sideways so that 20-90 % of its (nominal, ±0.15 m) angular extent is behind the first one.
    """
    ox, oy = (float(v) for v in rng.uniform(-1.2, 1.2, size=2))
    heading = float(rng.uniform(-math.pi, math.pi))
    yaw = float(rng.uniform(-YAW_LIMIT, YAW_LIMIT))
    w.set_pose(1, ox, oy, heading)
    view = heading + yaw
    ex = ox + cam.cam_forward * math.cos(view)
    ey = oy + cam.cam_forward * math.sin(view)
    placed: list[tuple[float, float]] = [(ox, oy)]
    seen: list[tuple[float, float]] = []
    roles: dict[int, str] = {}
    for j in range(n_others):
        rid = j + 2
        for attempt in range(200):
            if overlap and j == 1:  # partly behind the first neighbour
                d0, b0 = seen[0][0], seen[0][1]
                d = min(d0 + float(rng.uniform(0.45, 1.2)), max_distance + 0.1)
                h0, h = math.atan(HALF_WIDTH / d0), math.atan(HALF_WIDTH / d)
                covered = float(rng.uniform(0.2, 0.9))
                sgn = 1.0 if rng.random() < 0.5 else -1.0
                b = b0 + sgn * (h0 + h - 2.0 * h * covered)
                apart = True
            else:
                hi = max_distance - 0.45 if overlap and j == 0 else max_distance + 0.15
                d = float(rng.uniform(0.4, hi))
                b = float(rng.uniform(-math.radians(27), math.radians(27)))
                h = math.atan(HALF_WIDTH / d)
                # mostly unoccluded views: no overlap in the image with robots placed so far
                apart = attempt >= 150 or all(
                    abs(b - pb) > h + math.atan(HALF_WIDTH / pd) for pd, pb in seen
                )
            x, y = ox + d * math.cos(view + b), oy + d * math.sin(view + b)
            if (
                apart
                and all(math.hypot(x - px, y - py) > 0.45 for px, py in placed)
                and all(math.hypot(c.x - x, c.y - y) > 0.25 for c in clutter)
            ):
                break
        placed.append((x, y))
        seen.append((d, b))
        if overlap and j < 2:
            roles[rid] = ("front", "back")[j]
        w.set_pose(rid, x, y, float(rng.uniform(-math.pi, math.pi)))
    truths: list[Truth] = []
    for rid in w.robot_ids:  # every other robot, the parked ones too (for precision)
        if rid == 1:
            continue
        x, y, _ = w.pose(rid)
        dc = math.hypot(x - ex, y - ey)
        cb = wrap(math.atan2(y - ey, x - ex) - view)
        half = math.atan(HALF_WIDTH / max(dc, 1e-6))
        truths.append(
            Truth(
                robot=rid,
                distance=math.hypot(x - ox, y - oy),
                bearing=wrap(math.atan2(y - oy, x - ox) - heading),
                cam_bearing=cb,
                half_angle=half,
                in_view=abs(cb) + half <= cam.hfov / 2,
                max_distance=max_distance,
                role=roles.get(rid, ""),
            )
        )
    for t in truths:  # occlusion by any nearer robot whose extent overlaps
        for u in truths:
            overlap_img = abs(u.cam_bearing - t.cam_bearing) < u.half_angle + t.half_angle
            if u is not t and overlap_img:
                if u.distance < t.distance:
                    t.occluded = True
                elif u.in_view or abs(u.cam_bearing) - u.half_angle < cam.hfov / 2:
                    t.overlapped = True
    cz = cam.height_m
    for t in truths:  # orange clutter in front (occludes) or behind (overlaps) it
        dc = HALF_WIDTH / math.tan(t.half_angle)
        band = (math.atan((BAND[0] - cz) / dc), math.atan((BAND[1] - cz) / dc))
        for c in clutter:
            cdist = math.hypot(c.x - ex, c.y - ey)
            if cdist < 0.05:
                continue
            cb = wrap(math.atan2(c.y - ey, c.x - ex) - view)
            chalf = math.atan(c.size * 0.75 / cdist)
            lo = math.atan((c.z - c.size / 2 - cz) / cdist)
            hi = math.atan((c.z + c.size / 2 - cz) / cdist)
            if abs(cb - t.cam_bearing) < t.half_angle + chalf and lo < band[1] and hi > band[0]:
                if cdist < dc:
                    t.occluded = t.clutter_occluded = True
                else:
                    t.cluttered = True
    return yaw, truths


def visible_fractions(w: World, yaw: float, full: np.ndarray, truths: list[Truth]) -> None:
    """Measure each in-view robot's visible orange fraction (``Truth.visible``).

    Every robot in view is rendered alone (the others parked behind the observer); its
    own orange is what that adds to the view without robots (the clutter's orange), and
    a pixel of it counts as visible when the full view is orange there and no nearer
    robot's own orange covers it. Robots with no orange in view get 0.
    """
    from agent.core.perception.segmentation import orange_mask

    ox, oy, heading = w.pose(1)
    view = heading + yaw
    back = (-math.cos(view), -math.sin(view))  # parking spots behind the camera
    poses = {t.robot: w.pose(t.robot) for t in truths}

    def park(u: Truth) -> None:
        r = 1.5 + 0.5 * u.robot
        w.set_pose(u.robot, ox + r * back[0], oy + r * back[1], poses[u.robot][2])

    for u in truths:
        park(u)
    empty = orange_mask(w.render(1, yaw)) > 0  # the clutter's orange, no robot
    alone: dict[int, np.ndarray] = {}
    for t in truths:
        if not t.in_view:
            continue
        for u in truths:
            if u is t:
                w.set_pose(u.robot, *poses[u.robot])
            else:
                park(u)
        alone[t.robot] = (orange_mask(w.render(1, yaw)) > 0) & ~empty
    for u in truths:
        w.set_pose(u.robot, *poses[u.robot])
    full_mask = orange_mask(full) > 0
    for t in truths:
        if t.robot not in alone:
            continue
        own = alone[t.robot]
        seen = own & full_mask
        for u in truths:
            if u.robot in alone and u is not t and u.distance < t.distance:
                seen &= ~alone[u.robot]
        n = int(own.sum())
        t.visible = float(seen.sum()) / n if n else 0.0


def scenes(
    seed: int,
    n_views: int,
    clutter: bool,
    cam: CameraModel,
    neighbour_heads: bool = False,
    max_distance: float = RANGE[1],
    overlap: bool = False,
    renderer: str = "tiny",
    look: Look | None = None,
) -> Generator[Scene, None, None]:
    """``n_views`` labelled views of seed ``seed`` (a new world every
    ``VIEWS_PER_WORLD`` views, drawn by ``renderer`` in ``look``), seen by ``cam``; with ``overlap`` each view puts a NAO
    partly behind another and measures the visible fractions. Close the generator (or
    run it to the end) to close the last world."""
    if not RANGE[0] < max_distance <= 4.0:
        raise ValueError(f"max_distance must be in ({RANGE[0]}, 4.0] m, got {max_distance}")
    rng = np.random.default_rng([seed, 0xE7A1])
    w: World | None = None
    try:
        for v in range(n_views):
            if v % VIEWS_PER_WORLD == 0:
                if w is not None:
                    w.close()
                room = room_for(max_distance)
                w = make_world(rng, 3, clutter, seed * 1000 + v, room, renderer, look)
            assert w is not None
            n_others = int(rng.integers(2, 4)) if overlap else int(rng.integers(1, 4))
            for rid in range(n_others + 2, 5):  # park unused robots in a corner, facing the wall
                w.set_pose(rid, -3.3 + 0.5 * rid, -3.5, -math.pi / 2)
            yaw, truths = place(w, rng, cam, n_others, w.scenario.clutter, max_distance, overlap)
            for rid in w.robot_ids[1:]:  # the neighbours' heads: straight, or mid-sweep
                hy = float(rng.uniform(-YAW_LIMIT, YAW_LIMIT)) if neighbour_heads else 0.0
                w.set_head_yaw(rid, hy)
            img = w.render(1, yaw)
            if overlap:
                visible_fractions(w, yaw, img, truths)
            yield Scene(img, yaw, truths)
    finally:
        if w is not None:
            w.close()
