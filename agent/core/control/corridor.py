"""Safe steps under noise: check the corridor of the next step before taking it (execution noise
moves robots off their planned corridors).

The project's addition to NAO paper 4.2 and 5.2.2: the paper's robots walk their planned
segments open loop (20 cm steps, the heading corrected by the visual compass after each),
and the plan keeps every path 2·radius from every robot it may meet (agent/core/formation/waves
safety, execution). Execution noise moves robots off those corridors, so before each
step the robot looks at the NAOs in the image it already takes for the compass (head
yaw 0, straight ahead) and decides:

- **go** when no NAO stands within the clearance ``c = 2·radius + margin`` of the
  step's sweep: the segment from the robot's believed position to the end of the step
  and ``lookahead`` beyond it (at most to the goal). The lookahead flags a NAO standing
  beside the way while the image still shows it: checked one step ahead only, a NAO
  0.25 m beside the way blocks the step only once it is 0.6 m ahead, too near to be seen
  surely, and the robot crept past it (step back to see it, step on, the sighting lost
  beside the robot; at 100 NAOs, and ``tests/body/test_safe_steps.py``).
  A NAO the step does not approach (the closest point of the segment is its start:
  stepping away from a robot already close) does not block, as in
  :func:`agent.core.control.station.safe_walk`.
- **wait** while it is blocked and has waited fewer than :func:`patience` polls (the
  caller re-looks after each poll: the other NAO may be walking through).
- **via** after that: a step of the same length along the tangent to the circle of
  radius ``c + via_extra`` around the blocking NAO(s), on the side the blockers are not
  (the smaller detour); the other side if that step is blocked or would turn more
  than 90° off the way, else wait. The caller
  re-checks before every step, so a detour of several tangent steps follows the circle
  round the blocker (closed loop, a fresh image each step).

**Deadlock rule** (two robots waiting on each other forever, e.g. head-on): waiting is
bounded, and the bound depends on the robot's rank in the shared plan, the index of
(wave, robot id) in the sorted list of planned robots, which every agent computes alike:
:func:`patience` = ``base_polls + rank`` polls. Of two robots that block each other, the
one ranked earlier runs out of patience first and steps aside while the other still
waits and then finds its corridor clear. Should both step aside (the later one's patience
ran out too), the side rule has each pass the other on its right: each sees the other on
the same side of its own line (head-on: both see the other on their left up to the
noise; a tie within ``tie`` metres of the line is passed on the right), so the tangent
steps diverge.

**Memory** (the runner's): a NAO closer than about 0.5 m is cut by the image border and
not detected, and one beside the robot is outside the image; so the runner checks
against every NAO seen in the last ``memory_steps`` steps too (dead-reckoned, relative to
its believed position), and against those alone to decide whether a detour is over.
While it waits, a sighting that the next image would surely show again (:func:`in_view`:
believed at least :data:`FORGET_NEAR` away and :data:`FORGET_EDGE` inside the image) is
forgotten before that image is taken, so a NAO that walked on no longer blocks.

Backward steps (``walk`` < 0: the final correction's small moves back) are not checked:
the camera looks ahead. NAOs outside the image (beside the robot) are not seen; a step
of 20 cm only approaches those within ~0.2 m of the clearance, which the plan's slot
spacing (>= d_e) and the searched starts keep away.

Pure: arrays in, a :class:`Verdict` out; the agent's safe steps (agent/phases/safe_steps.py) look and move.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from agent.core.control.rotation import wrap_pi
from agent.core.formation.params import PlanParams

GO, WAIT, VIA = "go", "wait", "via"
RIGHT, LEFT = -1, 1  # the side of a via step: the sign of the normal (left of the heading)
MAX_VIA_TURN = math.pi / 2  # a via step turns at most this far off the way


def _finite(name: str, v: float, lo: float = -math.inf, hi: float = math.inf) -> float:
    f = float(v)
    if not (math.isfinite(f) and lo <= f <= hi):
        raise ValueError(f"{name} must be finite and in [{lo}, {hi}], got {v!r}")
    return f


@dataclass(frozen=True)
class CorridorParams:
    """The check's settings; ``radius`` is the planner's (PlanParams, one home)."""

    radius: float = field(default_factory=lambda: PlanParams().radius)
    margin: float = 0.05  # m added to 2·radius (the detector's range error at ~0.6 m)
    via_extra: float = 0.1  # m more than the clearance for a via step's tangent circle
    poll: float = 1.0  # s between looks while waiting
    base_polls: int = 1  # polls every robot waits before a via step (plus its rank)
    max_polls: int = 60  # polls of one blocking episode before the robot gives up
    tie: float = 0.05  # m: a blocker this close to the line is passed on the right
    memory_steps: int = 6  # steps a sighting is remembered (the runner's, see below)
    back_max: float = 0.15  # m: the longest step back to see a remembered NAO again
    #: m of the way beyond the step checked too (module docstring): a NAO at the
    #: sweep's end + lookahead >= VIEW_NEAR + 0.1 ahead is still surely in the image
    lookahead: float = 0.5

    def __post_init__(self) -> None:
        _finite("radius", self.radius, 1e-3, 5.0)
        _finite("margin", self.margin, 0.0, 1.0)
        _finite("via_extra", self.via_extra, 0.0, 1.0)
        _finite("poll", self.poll, 0.0, 60.0)
        _finite("tie", self.tie, 0.0, 1.0)
        _finite("back_max", self.back_max, 0.0, 0.5)
        _finite("lookahead", self.lookahead, 0.0, 2.0)
        if not 0 <= self.memory_steps <= 100:
            raise ValueError(f"memory_steps must be in [0, 100], got {self.memory_steps}")
        if not 0 <= self.base_polls <= self.max_polls:
            raise ValueError(
                f"base_polls must be in [0, max_polls={self.max_polls}], got {self.base_polls}"
            )

    @property
    def clearance(self) -> float:
        """c = 2·radius + margin: the distance a step's sweep keeps from every NAO."""
        return 2.0 * self.radius + self.margin


@dataclass(frozen=True)
class Verdict:
    """What to do before a step: ``action`` go / wait / via.

    ``blockers``: the NAOs blocking the step (k, 2), relative to the robot in the fixed
    frame, nearest first; ``heading``/``walk``: the via step (rad, m); ``side``: its side
    (RIGHT/LEFT, 0 without a via)."""

    action: str
    blockers: np.ndarray
    heading: float = 0.0
    walk: float = 0.0
    side: int = 0


def patience(rank: int, params: CorridorParams) -> int:
    """Polls a robot of plan rank ``rank`` waits before stepping aside (the deadlock rule)."""
    if rank < 0:
        raise ValueError(f"rank must be >= 0, got {rank}")
    return min(params.base_polls + rank, params.max_polls)


def plan_rank(order: list[tuple[int, int]], me: int) -> int:
    """The index of robot ``me`` in ``order`` = [(wave, robot id), ...] sorted."""
    ranked = sorted(order)
    for k, (_, rid) in enumerate(ranked):
        if rid == me:
            return k
    raise ValueError(f"robot {me} is not in the plan")


def _points(others: np.ndarray) -> np.ndarray:
    pts = np.asarray(others, dtype=np.float64).reshape(-1, 2)
    if not np.all(np.isfinite(pts)):
        raise ValueError("NAO positions must be finite")
    return pts


def closest_approach(end: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Per point of ``pts`` (k, 2), its distance to the segment from the origin to ``end``."""
    e = np.asarray(end, dtype=np.float64).reshape(2)
    n2 = float(e @ e)
    if n2 == 0.0:
        return np.asarray(np.hypot(pts[:, 0], pts[:, 1]), dtype=np.float64)
    t = np.clip(pts @ e / n2, 0.0, 1.0)
    return np.asarray(np.hypot(*(pts - t[:, None] * e).T), dtype=np.float64)


def blocking(walk: float, heading: float, others: np.ndarray, clearance: float) -> np.ndarray:
    """Mask of the NAOs at ``others`` (relative, fixed frame) that block a straight step of
    ``walk`` m along ``heading``: the sweep comes within ``clearance`` of them and closer
    than they are now."""
    _finite("walk", walk, -3.0, 3.0)
    _finite("heading", heading)
    _finite("clearance", clearance, 0.0)
    pts = _points(others)
    end = walk * np.array([math.cos(heading), math.sin(heading)])
    closest = closest_approach(end, pts)
    now = np.hypot(pts[:, 0], pts[:, 1])
    return np.asarray((closest < clearance) & (closest < now - 1e-9), dtype=bool)


#: m: the nearest a NAO is found again in a yaw-0 image (closer, the image cuts it)
VIEW_NEAR = 0.6
#: m: the nearest a remembered NAO may be *believed* for an image that does not show it to
#: forget it: VIEW_NEAR plus the range error of a step back and of the detector. At
#: 100 NAOs, robot 91 stepped back from robot 99 to a believed ~0.6 m, forgot it
#: when the next image did not show it (truly 0.58 m, 35° off its heading: outside the
#: image), walked on and touched it.
FORGET_NEAR = VIEW_NEAR + 0.1
#: rad: how far inside the field of view a remembered NAO must be believed for an image
#: that does not show it to forget it (a NAO's half width at 0.6 m is ~14°; the compass
#: drifts a few degrees over the remembered steps); beyond, the head looks at it.
FORGET_EDGE = math.radians(10.0)


def in_view(
    rel: np.ndarray,
    heading: float,
    hfov: float,
    near: float = FORGET_NEAR,
    far: float = 1.4,
    edge: float = FORGET_EDGE,
) -> np.ndarray:
    """Mask of the points ``rel`` (k, 2; relative, fixed frame) that an image along
    ``heading`` surely shows wholly, so that the detector finds them (``edge`` inside the
    field of view ``hfov``, range in [near, far]): a sighting there is seen again if it
    is still there, and forgotten if the image does not show it."""
    _finite("heading", heading)
    _finite("hfov", hfov, 0.0, 2 * math.pi)
    _finite("edge", edge, 0.0, math.pi)
    pts = _points(rel)
    rng = np.hypot(pts[:, 0], pts[:, 1])
    off = np.abs(np.angle(np.exp(1j * (np.arctan2(pts[:, 1], pts[:, 0]) - heading))))
    return np.asarray((off <= hfov / 2 - edge) & (rng >= near) & (rng <= far))


def confirmed(blocker: np.ndarray, seen: np.ndarray, params: CorridorParams) -> bool:
    """Whether a NAO of the current image (``seen``, (k, 2), relative) stands within
    ``2·margin`` of ``blocker`` (relative): the blocker is seen, not only remembered."""
    b = _points(blocker).reshape(-1)
    fresh = _points(seen)
    return bool(fresh.shape[0]) and float(np.min(np.hypot(*(fresh - b).T))) < 2.0 * params.margin


def back_off(
    blocker: np.ndarray, seen: np.ndarray, heading: float, hfov: float, params: CorridorParams
) -> float:
    """How far to step back (m, >= 0) to see a blocker that is only remembered.

    A NAO nearer than :data:`VIEW_NEAR` is cut by the image and not detected, so a waiting
    robot cannot tell whether a NAO it remembers there has walked away, and would wait
    for it to the end of its patience (seen with 15 robots: two robots ended a via
    0.52-0.58 m from NAOs that left 18 s later). When the first ``blocker`` (relative,
    fixed frame) is confirmed by no NAO of the current image (``seen``, (k, 2)), is not
    behind the robot (along ``heading``) and is nearer than :data:`FORGET_NEAR`, the robot
    steps back until it would be ``FORGET_NEAR + margin`` away, at most
    ``params.back_max`` per call: the image (yaw 0, or the head turned to it) then
    decides again. 0 otherwise.
    ``hfov`` is validated only (the field of view that decides is the caller's)."""
    _finite("heading", heading)
    _finite("hfov", hfov, 0.0, 2 * math.pi)
    b = _points(blocker)
    if b.shape[0] != 1:
        raise ValueError(f"one blocker expected, got {b.shape[0]}")
    rng = float(np.hypot(*b[0]))
    if confirmed(b[0], seen, params) or rng >= FORGET_NEAR:
        return 0.0  # the image shows it (wait for it), or it can be seen where it is
    u = np.array([math.cos(heading), math.sin(heading)])
    along = float(b[0] @ u)
    if along < 0.0:
        return 0.0  # behind: stepping back would come nearer
    want = FORGET_NEAR + params.margin
    # |b + d·u| = want: the robot moves -d·u, the blocker's relative position +d·u
    d = -along + math.sqrt(along * along - rng * rng + want * want)
    return min(params.back_max, d)


def _tangent(heading: float, blockers: np.ndarray, radius: float, side: int) -> float:
    """The heading that passes every blocker on ``side`` at >= ``radius`` (to first
    order): the most deviated of the tangents to their circles (or the perpendicular to
    one already within ``radius``: moving along it never comes closer)."""
    best = 0.0
    for x, y in blockers:
        rho = math.hypot(x, y)
        bearing = wrap_pi(math.atan2(y, x) - heading)
        half = math.asin(min(1.0, radius / rho)) if rho > 0 else math.pi / 2
        dev = wrap_pi(bearing + side * half)  # the tangent's offset from the heading
        if side * dev > side * best:
            best = dev
    return wrap_pi(heading + best)


def check_step(
    walk: float,
    heading: float,
    others: np.ndarray,
    params: CorridorParams,
    waited: int = 0,
    rank: int = 0,
    side: int = 0,
    goal: np.ndarray | None = None,
    ahead: float = 0.0,
    members: np.ndarray | None = None,
) -> Verdict:
    """Go, wait or via for a step of ``walk`` m along ``heading`` (believed, fixed frame)
    with NAOs at ``others`` (k, 2; relative to the robot, fixed-frame axes), after
    ``waited`` polls blocked, for the robot of plan rank ``rank``. ``side`` (RIGHT/LEFT)
    keeps a detour on the side it started; 0 chooses (see the module docstring).
    ``goal`` (relative): a blocker within the clearance of it cannot be walked round:
    wait. ``ahead`` (m, >= 0): the way beyond the step checked as well (the caller's
    ``lookahead``, cut at the goal); a via step itself is checked over its own length.

    ``members`` (m, 2; relative): where the members are by the plan and their statuses,
    seen or not (standing at their starts or slots, left out, or the next stretch of a
    walking member's path). A planned step needs no such check (the plan keeps its
    corridor clear of them in time); a via step is off the plan, so it must clear them
    as it clears the NAOs seen: a member in its way widens the tangent round it too (at
    most :data:`MAX_VIA_TURN` off the way). At 100 NAOs a detour's tangent steps passed
    0.39 m from a member standing at its start, too near and too far aside to be in any
    image, which then walked into it."""
    _finite("walk", walk, -1.0, 1.0)
    _finite("heading", heading)
    _finite("ahead", ahead, 0.0, 2.0)
    if waited < 0:
        raise ValueError(f"waited must be >= 0, got {waited}")
    if side not in (0, RIGHT, LEFT):
        raise ValueError(f"side must be RIGHT (-1), LEFT (1) or 0, got {side}")
    pts = _points(others)
    if walk <= 0.0:  # backwards: the camera does not see that way
        return Verdict(GO, np.zeros((0, 2)))
    c = params.clearance
    mask = blocking(walk + ahead, heading, pts, c)
    if not mask.any():
        return Verdict(GO, np.zeros((0, 2)))
    blockers = pts[mask]
    blockers = blockers[np.argsort(np.hypot(blockers[:, 0], blockers[:, 1]), kind="stable")]
    if waited < patience(rank, params):
        return Verdict(WAIT, blockers)
    if goal is not None and np.any(closest_approach(np.zeros(2), blockers - _points(goal)) < c):
        return Verdict(WAIT, blockers)  # it stands on the goal: no step round it helps
    if side == 0:
        # pass on the side the nearest blocker is not; a tie on the right
        x, y = blockers[0]
        lateral = -math.sin(heading) * x + math.cos(heading) * y  # > 0: on the left
        side = LEFT if lateral < -params.tie else RIGHT
    known = np.zeros((0, 2)) if members is None else _points(members)
    for s in (side, -side):
        avoid, still = blockers, known
        for _ in range(1 + len(known)):  # each pass adds a member in the way
            h = _tangent(heading, avoid, c + params.via_extra, s)
            if abs(wrap_pi(h - heading)) > MAX_VIA_TURN:
                break  # not a step round the blocker but away from the way
            if blocking(walk, h, pts, c).any():
                break
            hit = blocking(walk, h, still, c)
            if not hit.any():
                return Verdict(VIA, blockers, h, walk, s)
            avoid = np.vstack([avoid, still[hit]])
            still = still[~hit]
    return Verdict(WAIT, blockers)
