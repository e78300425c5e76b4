"""Walking and turning on the sim clock, with seeded noise and contacts.

NAO paper §4.2 and §5.2.2 (Table 2, Fig. 23): open-loop walking drifts; the heading error
grows with the length of a segment (about 0.02-0.23 rad after 0.2 m, 0.33-0.53 rad after
0.7-1.0 m), which is why the paper walks in 20 cm steps and corrects the heading with the
visual compass after each step.

**Motion.** ``walk(d)`` moves a robot straight ahead (``d`` < 0: backwards) at
:data:`WALK_SPEED` = 0.095 m/s (backwards :data:`BACK_SPEED`); ``turn(a)`` turns it on the
spot at :data:`TURN_RATE`; ``side(d)`` steps it sideways (``d`` > 0: to its left, NAOqi's
``moveTo(0, y, 0)``) at :data:`SIDE_SPEED`, at most :data:`~agent.wire.MAX_SIDE_STEP` at
once. All active commands advance together in fixed steps of
``dt`` = 0.02 s of sim time (:meth:`Locomotion.step`); a robot runs one command at a time.

**Noise model** (:class:`NoiseModel`, seeded per robot from the scenario seed and the
robot id, so results do not depend on what other robots do):

- walk distance: actual = commanded × (1 + N(0, 0.04));
- walk heading: a curvature κ = κ_r + κ_c plus a random walk of 0.10 rad/√m, where
  κ_r ~ N(0, 0.30 rad/m) is the robot's own drift (drawn once per robot: a NAO tends to
  veer to the same side, as the mostly positive long-distance errors of Table 2 show)
  and κ_c ~ N(0, 0.20 rad/m) is drawn per command. Over robots, after a segment of length
  s the heading error has σ = sqrt(0.13 s² + 0.01 s): 0.09 rad at 0.2 m, 0.37 rad at
  1.0 m (Table 2, one NAO: |e| 0.02-0.10 rad at 0.2 m, 0.33-0.45 rad at 0.8-1.0 m);
- sidestep: the walk's distance error and heading random walk (no curvature: the
  veer of a NAO is a property of its forward gait);
- turn: actual = commanded × (1 + N(0, 0.05)) + N(0, 0.02 rad).

:meth:`NoiseModel.scaled` multiplies every σ by K (``python -m sim --noise-scale K``,
for execution noise that moves robots off their planned corridors).

**Contacts.** Each robot is a disc of radius :data:`~sim.physics.nao_model.FOOTPRINT_RADIUS`
(0.155 m, half the NAO's 0.311 m depth); obstacles are discs of their radius; the walls
bound the room. A step that would bring a moving robot into overlap with another body
*while approaching it* is not taken: every robot involved stops, its command ends with
status ``contact``, and a :class:`Contact` (``b`` = -1 for an obstacle or a wall) is
reported and counted. A robot already touching may still move away.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Protocol

import numpy as np

from agent.wire import MAX_SIDE_STEP
from sim.physics.nao_model import FOOTPRINT_RADIUS

WALK_SPEED = 0.095  # m/s forwards (NAO default)
BACK_SPEED = 0.06  # m/s backwards
TURN_RATE = 0.6  # rad/s on the spot
SIDE_SPEED = 0.05  # m/s sideways
DT = 0.02  # s of sim time per step
MAX_DISTANCE = 50.0  # m, longest accepted walk command
MAX_ANGLE = 4 * math.pi  # rad, largest accepted turn command
MAX_NOISE_SCALE = 10.0  # largest accepted multiplier of the noise


@dataclass(frozen=True)
class NoiseModel:
    distance_scale: float = 0.04  # σ of the relative distance error
    curvature_bias: float = 0.30  # σ of each robot's own heading drift, rad per metre
    curvature: float = 0.20  # σ of the per-command heading drift, rad per metre
    heading_walk: float = 0.10  # σ of the heading random walk, rad per sqrt(metre)
    turn_scale: float = 0.05  # σ of the relative turn error
    turn_offset: float = 0.02  # σ of the absolute turn error, rad

    @staticmethod
    def none() -> NoiseModel:
        return NoiseModel(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)

    def scaled(self, k: float) -> NoiseModel:
        """Every σ multiplied by ``k`` (0: noiseless; at most :data:`MAX_NOISE_SCALE`)."""
        k = float(k)
        if not (math.isfinite(k) and 0.0 <= k <= MAX_NOISE_SCALE):
            raise ValueError(f"noise scale must be in [0, {MAX_NOISE_SCALE:g}], got {k!r}")
        return NoiseModel(*(k * getattr(self, f.name) for f in fields(self)))


@dataclass(frozen=True)
class Obstacle:
    x: float
    y: float
    radius: float


@dataclass(frozen=True)
class Done:
    """A finished command: ``status`` is ``done`` or ``contact``."""

    robot_id: int
    kind: str
    status: str
    t_sim: float
    detail: str = ""


@dataclass(frozen=True)
class Contact:
    """A contact between robot ``a`` and robot ``b`` (-1: an obstacle or a wall)."""

    a: int
    b: int
    t_sim: float


class Poses(Protocol):
    """What locomotion needs from the world."""

    robot_ids: tuple[int, ...]

    def pose(self, robot_id: int) -> tuple[float, float, float]: ...

    def set_pose(self, robot_id: int, x: float, y: float, heading: float) -> None: ...


@dataclass
class _Motion:
    kind: str  # "walk", "side" or "turn"
    remaining: float  # metres of path or radians of turn still to go (>= 0)
    sign: float  # direction of travel / turn
    speed: float  # m/s or rad/s
    curvature: float  # rad per metre (walks)


class Locomotion:
    """Concurrent walk/turn commands for the robots of ``world`` on a sim clock."""

    def __init__(
        self,
        world: Poses,
        *,
        seed: int,
        noise: NoiseModel | None = None,
        obstacles: tuple[Obstacle, ...] = (),
        room: float = math.inf,
        dt: float = DT,
    ) -> None:
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"time step {dt} must be positive")
        self.world = world
        self.noise = noise if noise is not None else NoiseModel()
        self.obstacles = obstacles
        self.room = room
        self.dt = dt
        self.t_sim = 0.0
        self.contacts = 0
        self._rngs = {
            rid: np.random.default_rng([seed, rid, 0x1E65]) for rid in sorted(world.robot_ids)
        }
        # Each robot's own drift: the first draw of its generator.
        self.drift = {
            rid: self.noise.curvature_bias * float(rng.standard_normal())
            for rid, rng in self._rngs.items()
        }
        self._active: dict[int, _Motion] = {}

    # ------------------------------------------------------------------ commands

    def busy(self, robot_id: int) -> bool:
        return robot_id in self._active

    @property
    def active(self) -> int:
        """Number of robots with a command in progress."""
        return len(self._active)

    def _check_free(self, robot_id: int) -> np.random.Generator:
        rng = self._rngs.get(robot_id)
        if rng is None:
            raise ValueError(f"unknown robot {robot_id!r}")
        if robot_id in self._active:
            raise ValueError(f"robot {robot_id} is busy with a {self._active[robot_id].kind}")
        return rng

    def _stride(
        self, robot_id: int, distance: float, bound: float, what: str
    ) -> tuple[np.random.Generator, float, float]:
        """(the robot's rng, the distance it will really cover, the direction ±1) of a
        walk or sidestep of ``distance`` m (at most ``bound``): the distance noise drawn."""
        d = float(distance)
        if not math.isfinite(d):
            raise ValueError(f"{what} {distance!r} is not finite")
        if abs(d) > bound:
            raise ValueError(f"{what} {d} m exceeds ±{bound} m")
        rng = self._check_free(robot_id)
        actual = abs(d) * max(0.0, 1.0 + self.noise.distance_scale * float(rng.standard_normal()))
        return rng, actual, 1.0 if d >= 0 else -1.0

    def walk(self, robot_id: int, distance: float) -> None:
        """Start walking ``distance`` metres straight ahead (negative: backwards)."""
        rng, actual, sign = self._stride(robot_id, distance, MAX_DISTANCE, "walk distance")
        kappa = self.drift[robot_id] + self.noise.curvature * float(rng.standard_normal())
        speed = WALK_SPEED if sign > 0 else BACK_SPEED
        self._active[robot_id] = _Motion("walk", actual, sign, speed, kappa)

    def side(self, robot_id: int, distance: float) -> None:
        """Start stepping ``distance`` metres sideways (positive: to the left)."""
        _, actual, sign = self._stride(robot_id, distance, MAX_SIDE_STEP, "sidestep")
        self._active[robot_id] = _Motion("side", actual, sign, SIDE_SPEED, 0.0)

    def turn(self, robot_id: int, angle: float) -> None:
        """Start turning on the spot by ``angle`` radians (positive: counter-clockwise)."""
        a = float(angle)
        if not math.isfinite(a):
            raise ValueError(f"turn angle {angle!r} is not finite")
        if abs(a) > MAX_ANGLE:
            raise ValueError(f"turn angle {a} rad exceeds ±{MAX_ANGLE:.3f} rad")
        rng = self._check_free(robot_id)
        n = self.noise
        actual = a * (1.0 + n.turn_scale * float(rng.standard_normal()))
        actual += n.turn_offset * float(rng.standard_normal())
        self._active[robot_id] = _Motion(
            "turn", abs(actual), 1.0 if actual >= 0 else -1.0, TURN_RATE, 0.0
        )

    # ------------------------------------------------------------------ stepping

    def step(self, clock: bool = False) -> tuple[list[Done], list[Contact]]:
        """Advance every active command by one ``dt``; the finished ones and the contacts.

        Robots are processed in id order (documented tie-break: when two robots would
        both enter contact in the same step, both stop and one contact is reported).
        With no command active the clock stands still, unless ``clock`` (a robot is
        looking: :mod:`sim.server.glances`), which advances it by ``dt`` all the same.
        """
        if not self._active:
            if clock:
                self.t_sim += self.dt
            return [], []
        self.t_sim += self.dt
        done: list[Done] = []
        contacts: list[Contact] = []
        stopped: set[int] = set()
        poses = {rid: self.world.pose(rid) for rid in self.world.robot_ids}
        proposal: dict[int, tuple[float, float, float]] = {}
        for rid in sorted(self._active):
            m = self._active[rid]
            x, y, th = poses[rid]
            if m.kind == "turn":
                dth = min(m.remaining, m.speed * self.dt)
                m.remaining -= dth
                proposal[rid] = (x, y, th + m.sign * dth)
            else:
                ds = min(m.remaining, m.speed * self.dt)
                m.remaining -= ds
                rng = self._rngs[rid]
                dth = m.curvature * ds
                if self.noise.heading_walk > 0 and ds > 0:
                    dth += self.noise.heading_walk * math.sqrt(ds) * float(rng.standard_normal())
                mid = th + dth / 2 + (math.pi / 2 if m.kind == "side" else 0.0)
                proposal[rid] = (
                    x + m.sign * ds * math.cos(mid),
                    y + m.sign * ds * math.sin(mid),
                    th + dth,
                )
        # Contacts: a moving robot's proposed position against every other body. A
        # vectorised pass finds the few pairs close enough to matter (a robot moves at
        # most a few mm per step); the exact test below runs on those only.
        ids = sorted(poses)
        r2 = 2 * FOOTPRINT_RADIUS
        near = self._near_pairs(ids, poses, proposal, r2 + 0.05)
        for rid in sorted(proposal):
            nx, ny, _ = proposal[rid]
            ox, oy, _ = poses[rid]
            if nx == ox and ny == oy:
                continue
            for other in near.get(rid, ()):
                px, py, _ = proposal.get(other, poses[other])
                if other in stopped:
                    px, py, _ = poses[other]
                d_new = math.hypot(nx - px, ny - py)
                if d_new < r2 and d_new < math.hypot(ox - px, oy - py):
                    if not (other in stopped and rid in stopped):
                        contacts.append(Contact(min(rid, other), max(rid, other), self.t_sim))
                    stopped.update((rid, other))
            for ob in self.obstacles:
                d_new = math.hypot(nx - ob.x, ny - ob.y)
                if d_new < FOOTPRINT_RADIUS + ob.radius and d_new < math.hypot(
                    ox - ob.x, oy - ob.y
                ):
                    contacts.append(Contact(rid, -1, self.t_sim))
                    stopped.add(rid)
            lim = self.room - FOOTPRINT_RADIUS
            if max(abs(nx), abs(ny)) > lim and max(abs(nx), abs(ny)) > max(abs(ox), abs(oy)):
                contacts.append(Contact(rid, -1, self.t_sim))
                stopped.add(rid)
        self.contacts += len(contacts)
        for rid in sorted(proposal):
            if rid in stopped:
                continue
            self.world.set_pose(rid, *proposal[rid])
        for rid in sorted(self._active):
            m = self._active[rid]
            if rid in stopped:
                others = sorted({c.b if c.a == rid else c.a for c in contacts if rid in (c.a, c.b)})
                what = ", ".join("obstacle/wall" if o == -1 else f"robot {o}" for o in others)
                done.append(Done(rid, m.kind, "contact", self.t_sim, f"contact with {what}"))
                del self._active[rid]
            elif m.remaining <= 1e-12:
                done.append(Done(rid, m.kind, "done", self.t_sim))
                del self._active[rid]
        # Stationary robots that were bumped have no command to end; nothing more to do.
        return done, contacts

    @staticmethod
    def _near_pairs(
        ids: list[int],
        poses: dict[int, tuple[float, float, float]],
        proposal: dict[int, tuple[float, float, float]],
        radius: float,
    ) -> dict[int, list[int]]:
        """For every moving robot, the other robots (sorted) within ``radius`` of it."""
        if len(ids) < 2:
            return {}
        pos = np.array([proposal.get(r, poses[r])[:2] for r in ids], dtype=np.float64)
        moving = np.array([r in proposal for r in ids])
        diff = pos[moving][:, None, :] - pos[None, :, :]
        close = np.einsum("ijk,ijk->ij", diff, diff) < radius * radius
        movers = [r for r in ids if r in proposal]
        out: dict[int, list[int]] = {}
        for a, rid in enumerate(movers):
            out[rid] = [ids[k] for k in np.flatnonzero(close[a]) if ids[k] != rid]
        return out

    def run_until_idle(self, max_time: float = 3600.0) -> tuple[list[Done], list[Contact]]:
        """Step until no command is active (for tests and tools)."""
        all_done: list[Done] = []
        all_contacts: list[Contact] = []
        t_end = self.t_sim + max_time
        while self._active and self.t_sim < t_end:
            d, c = self.step()
            all_done.extend(d)
            all_contacts.extend(c)
        return all_done, all_contacts
