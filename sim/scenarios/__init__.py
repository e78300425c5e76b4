"""Scenarios of the simulated world: robots, obstacles, clutter, lighting, seed.

A scenario fixes everything the world needs to start (docs/design.md §4): robot ids
and initial poses ``(x, y, heading)`` in world metres/radians, static obstacles (cylinders,
radius :data:`agent.core.nao.OBSTACLE_RADIUS` by default), optional orange lookalike clutter for the detector's hard
cases, the light, the seed of the textures and of the motion noise, the half-size of
the square room and the world's look (:mod:`sim.camera.look`; in JSON its SPEC text under
``look``, written only when it is not the default, so render workers draw the same).

:func:`generate` draws the paper-like starts of the NAO paper's experiments (§5.2.2):
every robot faces the same "north" (world +y, heading pi/2), nearest spacing 0.6-1.2 m,
every robot within the range of sight [DETECT_MIN, DETECT_MAX] = [0.5, 3.0] m (the
perception's, :data:`agent.core.nao.SIGHT_MAX`) of at least one other, the whole fleet
connected by that relation. With ``isolated`` one robot stands 2-3 m from every other
(at the far end of sight). ``headings`` leaves the papers' alignment (docs/design.md §9):
``aligned`` (every robot faces north, the default), ``random`` (uniform over the
circle) or ``jitter:DEG`` (north ± DEG degrees, uniform), drawn from a stream of their own
so that the positions of a seed do not depend on them. Scenario files are JSON
(:func:`load`, :func:`dump`).
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from agent.wire import nao
from sim.camera.look import Look

NORTH = math.pi / 2
MIN_SPACING = 0.6
MAX_SPACING = 1.2
DETECT_MIN = nao.SIGHT_MIN
DETECT_MAX = nao.SIGHT_MAX
ISOLATED_MIN = 2.0  # m: ``generate(isolated=True)``'s robot is 2 m to DETECT_MAX from the others
ROOM_MARGIN = 1.8  # metres between the outermost robot and a wall
MIN_ROOM = 3.0  # smallest room half-size (a 6 m x 6 m room)
MIN_BODY_GAP = 0.31  # two NAO footprints (radius 0.155 m) must not overlap
HEADINGS_HELP = "start headings: aligned (all north), random (uniform), jitter:DEG (north ± DEG)"
#: Salt of the start headings' random stream (``numpy.random.default_rng([seed, salt])``).
_HEADING_STREAM = 0x4E414F


@dataclass(frozen=True)
class Headings:
    """How a generated scenario's robots face at the start (module docstring)."""

    kind: str = "aligned"  # aligned | random | jitter
    spread_deg: float = 0.0  # jitter: the half-width of the uniform spread

    @classmethod
    def parse(cls, text: str) -> Headings:
        """``aligned``, ``random`` or ``jitter:DEG`` (0 < DEG <= 180); ``ValueError`` else."""
        if text in ("aligned", "random"):
            return cls(text)
        kind, _, deg = text.partition(":")
        if kind == "jitter" and deg:
            try:
                spread = float(deg)
            except ValueError:
                spread = math.nan
            if math.isfinite(spread) and 0.0 < spread <= 180.0:
                return cls("jitter", spread)
        raise ValueError(
            f"headings {text!r}: expected aligned, random or jitter:DEG (0 < DEG <= 180)"
        )

    def __str__(self) -> str:
        return f"jitter:{self.spread_deg:g}" if self.kind == "jitter" else self.kind

    def draw(self, n: int, seed: int) -> list[float]:
        """The start headings (rad, CCW from +x, rounded to 1e-6) of robots 1..n."""
        if self.kind == "aligned":
            return [NORTH] * n
        rng = np.random.default_rng([seed, _HEADING_STREAM])
        if self.kind == "random":
            raw = rng.uniform(-math.pi, math.pi, size=n)
        else:
            half = math.radians(self.spread_deg)
            raw = NORTH + rng.uniform(-half, half, size=n)
        return [round(float(math.remainder(h, 2 * math.pi)), 6) for h in raw]


@dataclass(frozen=True)
class RobotSpec:
    """One NAO: id and initial pose (world metres; heading rad CCW from +x)."""

    id: int
    x: float
    y: float
    heading: float = NORTH


@dataclass(frozen=True)
class ObstacleSpec:
    """A static cylinder standing on the floor (obstacle rose, 0.6 m tall; agent/core/nao.py)."""

    x: float
    y: float
    radius: float = nao.OBSTACLE_RADIUS


@dataclass(frozen=True)
class ClutterSpec:
    """An orange lookalike cube (the detector's colour) centred at (x, y, z), edge ``size``."""

    x: float
    y: float
    z: float
    size: float


@dataclass(frozen=True)
class LightSpec:
    """Lighting: ``intensity`` scales the diffuse light (1.0 = default), ``azimuth`` and
    ``elevation`` (rad) give the direction the light comes from."""

    intensity: float = 1.0
    azimuth: float = math.radians(30.0)
    elevation: float = math.radians(60.0)


@dataclass(frozen=True)
class Scenario:
    robots: tuple[RobotSpec, ...]
    obstacles: tuple[ObstacleSpec, ...] = ()
    clutter: tuple[ClutterSpec, ...] = ()
    light: LightSpec = field(default_factory=LightSpec)
    seed: int = 0
    room: float = 4.0  # half-size of the square room, metres (walls at x, y = +-room)
    look: Look = field(default_factory=Look)

    def __post_init__(self) -> None:
        validate(self)


def validate(sc: Scenario) -> None:
    """Raise ``ValueError`` if the scenario cannot be built."""
    if not sc.robots:
        raise ValueError("scenario has no robots")
    ids = [r.id for r in sc.robots]
    if len(set(ids)) != len(ids):
        raise ValueError(f"duplicate robot ids in {sorted(ids)}")
    if not (math.isfinite(sc.room) and 1.0 <= sc.room <= 100.0):
        raise ValueError(f"room half-size {sc.room} outside [1, 100] m")
    for r in sc.robots:
        if isinstance(r.id, bool) or not isinstance(r.id, int) or not 0 <= r.id <= 65535:
            raise ValueError(f"robot id {r.id!r} is not an int in [0, 65535]")
        for v in (r.x, r.y, r.heading):
            if not math.isfinite(v):
                raise ValueError(f"robot {r.id}: pose value {v} is not finite")
        if max(abs(r.x), abs(r.y)) > sc.room - 0.3:
            raise ValueError(f"robot {r.id} at ({r.x}, {r.y}) is outside the room ±{sc.room}")
    rs = sorted(sc.robots, key=lambda r: r.id)
    for i, a in enumerate(rs):
        for b in rs[i + 1 :]:
            if math.hypot(a.x - b.x, a.y - b.y) < MIN_BODY_GAP:
                raise ValueError(
                    f"robots {a.id} and {b.id} overlap: centres "
                    f"{math.hypot(a.x - b.x, a.y - b.y):.3f} m apart, at least {MIN_BODY_GAP} m"
                )
    for o in sc.obstacles:
        if not (math.isfinite(o.x) and math.isfinite(o.y) and 0.01 <= o.radius <= 5.0):
            raise ValueError(f"bad obstacle {o}")
        for r in rs:
            if math.hypot(o.x - r.x, o.y - r.y) < o.radius + MIN_BODY_GAP / 2:
                raise ValueError(f"obstacle at ({o.x}, {o.y}) overlaps robot {r.id}")
    for c in sc.clutter:
        if not all(math.isfinite(v) for v in (c.x, c.y, c.z)) or not 0.005 <= c.size <= 1.0:
            raise ValueError(f"bad clutter {c}")
    li = sc.light
    if not (math.isfinite(li.intensity) and 0.0 <= li.intensity <= 3.0):
        raise ValueError(f"light intensity {li.intensity} outside [0, 3]")
    if not isinstance(sc.look, Look):
        raise ValueError(f"look {sc.look!r} is not a Look")


def generate(
    n: int,
    seed: int,
    *,
    obstacles: int = 0,
    clutter: int = 0,
    light: LightSpec | None = None,
    isolated: bool = False,
    headings: Headings | None = None,
) -> Scenario:
    """Paper-like starts for ``n`` robots (ids 1..n), seeded; all facing north unless
    ``headings`` says otherwise (:class:`Headings`).

    Robots are placed one after another: each new robot picks an already placed one
    (uniformly), a direction (uniform) and a distance in [0.6, 1.2] m from it, and is kept
    if it is at least 0.6 m from every robot placed so far (else redrawn). Every robot is
    therefore within [0.6, 1.2] ⊂ [DETECT_MIN, DETECT_MAX] m of the robot it was attached
    to, and the fleet is connected. ``isolated`` (n >= 2): the last robot (id n) is
    placed the same way but at [ISOLATED_MIN, DETECT_MAX] = [2, 3] m from the robot it is
    attached to and at least ISOLATED_MIN from every other, so its nearest neighbour is
    2-3 m away (the robots 1..n-1 stand as in ``generate(n - 1, seed)``, up to the
    centring). The fleet is then centred on the room's centre (rounded to mm). ``obstacles`` cylinders and
    ``clutter`` orange cubes are put at least 0.8 m from every robot.
    """
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= 200:
        raise ValueError(f"robot count {n!r} must be an int in [1, 200]")
    if obstacles < 0 or clutter < 0:
        raise ValueError("obstacle and clutter counts must be >= 0")
    if isolated and n < 2:
        raise ValueError("an isolated robot needs at least 2 robots")
    rng = np.random.default_rng(seed)
    pts: list[tuple[float, float]] = [(0.0, 0.0)]
    tries = 0
    while len(pts) < n:
        tries += 1
        if tries > 100_000:
            raise ValueError(f"could not place {n} robots")
        lone = isolated and len(pts) == n - 1
        lo, hi = (ISOLATED_MIN, DETECT_MAX) if lone else (MIN_SPACING, MAX_SPACING)
        px, py = pts[int(rng.integers(len(pts)))]
        a = float(rng.uniform(0.0, 2 * math.pi))
        d = float(rng.uniform(lo, hi))
        q = (px + d * math.cos(a), py + d * math.sin(a))
        if all(math.hypot(q[0] - x, q[1] - y) >= lo for x, y in pts):
            pts.append(q)
    arr = np.array(pts)
    arr -= (arr.max(axis=0) + arr.min(axis=0)) / 2.0
    arr = np.round(arr, 3)
    half = max(MIN_ROOM, float(np.abs(arr).max()) + ROOM_MARGIN)
    half = math.ceil(half * 2.0) / 2.0
    faces = (headings or Headings()).draw(n, seed)
    robots = tuple(RobotSpec(i + 1, float(x), float(y), faces[i]) for i, (x, y) in enumerate(arr))

    def free_spot(min_d: float) -> tuple[float, float]:
        for _ in range(10_000):
            x, y = (float(v) for v in rng.uniform(-half + 0.5, half - 0.5, size=2))
            if all(math.hypot(x - r.x, y - r.y) >= min_d for r in robots):
                return round(x, 3), round(y, 3)
        raise ValueError("no free spot for an obstacle or clutter item")

    obs = tuple(ObstacleSpec(*free_spot(0.8)) for _ in range(obstacles))
    clt_list = []
    for _ in range(clutter):
        x, y = free_spot(0.8)
        size = round(float(rng.uniform(0.03, 0.08)), 3)
        z = round(float(rng.uniform(size / 2, 0.7)), 3)
        clt_list.append(ClutterSpec(x, y, z, size))
    return Scenario(
        robots=robots,
        obstacles=obs,
        clutter=tuple(clt_list),
        light=light if light is not None else LightSpec(),
        seed=seed,
        room=half,
    )


def to_dict(sc: Scenario) -> dict[str, Any]:
    """The scenario as JSON-ready data; its look as SPEC text, only when not the default."""
    d = asdict(sc)
    del d["look"]
    if not sc.look.is_default():
        d["look"] = str(sc.look)
    return d


def from_dict(d: Any) -> Scenario:
    """Build a scenario from parsed JSON; ``ValueError`` with the reason if it does not fit."""
    if not isinstance(d, dict):
        raise ValueError("scenario must be a JSON object")
    unknown = set(d) - {"robots", "obstacles", "clutter", "light", "seed", "room", "look"}
    if unknown:
        raise ValueError(f"unknown scenario keys {sorted(unknown)}")
    try:
        robots = tuple(RobotSpec(**r) for r in d["robots"])
        obstacles = tuple(ObstacleSpec(**o) for o in d.get("obstacles", []))
        clutter = tuple(ClutterSpec(**c) for c in d.get("clutter", []))
        light = LightSpec(**d.get("light", {}))
        kw: dict[str, Any] = {}
        if "room" in d:
            kw["room"] = float(d["room"])
        if "look" in d:
            if not isinstance(d["look"], str):
                raise ValueError(f"look {d['look']!r} is not a SPEC string")
            kw["look"] = Look.parse(d["look"])
        seed = d.get("seed", 0)
        if isinstance(seed, bool) or not isinstance(seed, int):
            raise ValueError(f"seed {seed!r} is not an int")
        return Scenario(robots, obstacles, clutter, light, seed, **kw)
    except KeyError as exc:
        raise ValueError(f"scenario is missing {exc}") from None
    except TypeError as exc:
        raise ValueError(f"bad scenario entry: {exc}") from None


def load(path: str | Path) -> Scenario:
    """Read a scenario JSON file."""
    try:
        data = json.loads(Path(path).read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not JSON: {exc}") from None
    return from_dict(data)


def dump(scenario: Scenario, path: str | Path) -> None:
    """Write a scenario JSON file (readable by :func:`load`)."""
    Path(path).write_text(json.dumps(to_dict(scenario), indent=2) + "\n")


def builtin(name: str) -> Path:
    """Path of a scenario file shipped in ``sim/scenarios/``."""
    p = Path(__file__).with_name(f"{name}.json")
    if not p.exists():
        raise ValueError(f"no built-in scenario {name!r}")
    return p
