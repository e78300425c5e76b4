"""A run as Foxglove draws it: the channels the recorder writes beside the raw wire
channels (docs/design.md §10 "Seeing the fleet"; docs/agent.md "Recordings").

:class:`Scene` takes what the observer sees on the bus (ground truth, statuses, records,
digests, contacts) and emits JSON messages of Foxglove's well-known schemas
(:mod:`tools.harness.view.foxglove`):

* ``/scene`` (``foxglove.SceneUpdate``), one per truth sample: every robot at its
  ground-truth pose, a cylinder of the NAO's footprint and height, an arrow for its
  heading and a label "id phase wave".
* ``/scene/obstacles``: the world's obstacles, once (given, or from the scenario file the
  harness wrote beside the recording during this run).
* ``/scene/plan``, once the plan is known: each robot's target (a disc, an arrow of the
  final heading), its path (start, via points, target), the links child → parent of the
  shape's tree, the obstacles the fleet planned around. The plan is the evaluator's (as
  :func:`tools.harness.judge.plan_from_agreed`): recomputed from the records the robots
  signed with the fleet's planning parameters (``params``: d_e, φ_e, orientation,
  strategy and shape, as the agents were given them; with other parameters the digest
  differs and nothing is drawn), drawn only when its digest is one an agent reported;
  with the orientation ``cp`` the formation's plan from the circle counts too, and so
  does each reshape an operator commanded (the transition from the plan it names, as
  every agent plans it: :func:`agent.core.formation.reshape.transition_plan`); the
  newest the agents reported is drawn. Its common frame is placed in the world by the
  frame robot's first ground-truth pose (``judge.summarise``'s ``turn``). It is computed
  when an agent reports a plan digest not drawn yet and the records, the ground truth or
  the reported digests changed since it last planned (so that the live view shows it while
  the fleet walks, also when a record reaches the observer after the first status that
  names the plan), and again when the recording closes; each drawing replaces the
  topic's earlier one, stamped with the world time of the first status that reported
  that digest.
* ``/tf`` (``foxglove.FrameTransform``): world → ``robot/{id}`` per truth sample, and
  world → ``common`` with the plan.
* ``/log`` (``foxglove.Log``): every change of a robot's phase, wave or error (the
  failure reason at level ERROR), records and digests (DEBUG), contacts (WARNING), and the
  recorder's own notes (why a plan or the obstacles are not drawn).
* ``/robots/{id}/status``: each status message as JSON (schema ``nao.Status``), for the
  Raw Messages and Plot panels (Foxglove cannot decode the msgpack channels).
* ``/nao/{id}/camera`` (``foxglove.CompressedImage``, format ``jpeg``, frame
  ``nao{id}/camera``): each camera frame robot ``id`` published (``--publish-camera``,
  ``agent.wire.CameraMsg``), and ``/nao/{id}/camera/annotations``
  (``foxglove.ImageAnnotations``, the same timestamp): a box per detection in the robot's
  colour, labelled with its number and distance, and the head yaw.

Time: every message is stamped with the world time (``t_sim``) of the latest truth sample
the caller has seen (``t_ns``), so the viewer's timeline is the world's clock.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, fields
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from agent.core.formation.params import PlanParams
from agent.core.formation.plan import Plan, RobotPlan
from agent.core.nao import OBSTACLE_HEIGHT, OBSTACLE_RGBA
from agent.wire import (
    CameraMsg,
    ContactMsg,
    DigestMsg,
    NeighborRecordMsg,
    ReshapeMsg,
    StatusMsg,
    TruthPosesMsg,
    id_from_key,
    reason,
)
from sim.physics.nao_model import FOOTPRINT_RADIUS, HEIGHT
from tools.harness.view import foxglove as fg
from tools.harness.view.foxglove import JSON
from tools.lib.frame_fit import common_frame_pose

#: The colours of matplotlib's ``tab10``, as the formation figure gives them: the k-th
#: robot in ascending id order of the first truth sample.
PALETTE = (
    (0.122, 0.467, 0.706), (1.000, 0.498, 0.055), (0.173, 0.627, 0.173),
    (0.839, 0.153, 0.157), (0.580, 0.404, 0.741), (0.549, 0.337, 0.294),
    (0.890, 0.467, 0.761), (0.498, 0.498, 0.498), (0.737, 0.741, 0.133),
    (0.090, 0.745, 0.812),
)  # fmt: skip
GREY = (0.55, 0.55, 0.55)
RECORDER = "recorder"  # the /log name of the recorder's own notes
#: A file's modification time comes from the kernel's coarse clock, a few ms behind
#: ``time.time_ns()``: a scenario file this much older than the recording still counts.
MTIME_SLACK_NS = 1_000_000_000


def _status_schema() -> JSON:
    kinds = {"int": "integer", "float": "number", "str": "string"}
    props: dict[str, JSON] = {}
    for f in fields(StatusMsg):
        name = f.type if isinstance(f.type, str) else f.type.__name__
        props[f.name] = {"type": kinds[name]}
    return {"title": "nao.Status", "type": "object", "properties": props, "required": list(props)}


#: A robot's status as JSON (agent/wire/messages.py ``StatusMsg``).
STATUS = _status_schema()


class Emit(Protocol):
    """Writes one JSON ``message`` of ``schema`` on ``topic`` at world time ``t_ns``."""

    def __call__(self, topic: str, schema: JSON, message: JSON, t_ns: int) -> None: ...


def to_world(p: npt.ArrayLike, frame: tuple[float, float, float]) -> tuple[float, float]:
    """A point of the common frame in the world: the common frame is the frame robot's
    fixed frame, the world turned by its start heading off north (``turn = h - π/2``) and
    moved to its start position; ``frame`` is that start pose (x, y, h)."""
    px, py = (float(v) for v in np.asarray(p, dtype=np.float64).reshape(2))
    x, y, h = frame
    turn = h - math.pi / 2
    c, s = math.cos(turn), math.sin(turn)
    return x + c * px - s * py, y + s * px + c * py


class Scene:
    """The Foxglove channels of one run, fed message by message (module docstring).

    ``params``: the fleet's planning parameters (default: the demo's); ``obstacles``: the
    world's (x, y, radius) if the caller knows them, else ``scenario`` (a scenario file)
    is read at the first truth sample when it was written at or after ``since_ns``
    (wall clock, ns; less :data:`MTIME_SLACK_NS`): the harness writes it beside the
    recording only for the runs that need one.
    """

    def __init__(
        self,
        emit: Emit,
        params: PlanParams | None = None,
        obstacles: Sequence[tuple[float, float, float]] | None = None,
        scenario: Path | None = None,
        since_ns: int = 0,
    ) -> None:
        self.emit = emit
        self.params = params or PlanParams()
        self.obstacles = None if obstacles is None else list(obstacles)
        self.scenario = scenario
        self.since_ns = since_ns
        self.starts: dict[int, tuple[float, float, float]] = {}
        self.order: list[int] = []
        self.phase: dict[int, StatusMsg] = {}
        self.changes: dict[int, tuple[str, int, str]] = {}
        self.records: dict[int, NeighborRecordMsg] = {}
        self.digests: dict[int, str] = {}
        #: each plan digest an agent reported → world time (ns) of its first report
        self.claimed: dict[str, int] = {}
        self.plan_drawn = ""
        #: the operator's reshape commands seen, by command number (the newest of each)
        self.commands: dict[int, ReshapeMsg] = {}
        #: bumped by every record or reshape command that changes what the planner is given
        self.records_seen = 0
        #: (records seen, robots with a start, digests reported) at the last live try
        self.plan_tried: tuple[int, int, int] = (-1, -1, -1)
        self.now_ns = 0  # the latest world time seen (ns)

    # ----------------------------------------------------------------- intake

    def take(self, key: str, msg: Any, t_ns: int) -> None:
        """One observed message (``key``: its bus key) at world time ``t_ns``."""
        self.now_ns = max(self.now_ns, t_ns)
        if isinstance(msg, TruthPosesMsg):
            self._truth(msg, t_ns)
        elif isinstance(msg, StatusMsg):
            self._status(msg, t_ns)
        elif isinstance(msg, NeighborRecordMsg):
            old = self.records.get(msg.sender)
            if (old is None or old.round <= msg.round) and old != msg:  # the newest round
                self.records[msg.sender] = msg
                self.records_seen += 1
            if old is None or old.round != msg.round:
                text = f"record round {msg.round}: {len(msg.neighbours)} neighbours"
                self._log(t_ns, fg.DEBUG, msg.sender, text + f", {len(msg.obstacles)} obstacles")
        elif isinstance(msg, DigestMsg):
            if self.digests.get(msg.sender) != msg.digest:
                self.digests[msg.sender] = msg.digest
                text = f"digest {msg.digest[:12]} over {list(msg.members)} (round {msg.round})"
                self._log(t_ns, fg.DEBUG, msg.sender, text)
        elif isinstance(msg, CameraMsg):
            self._camera(key, msg, t_ns)
        elif isinstance(msg, ReshapeMsg):
            if self.commands.get(msg.command) != msg:
                self.commands[msg.command] = msg
                self.records_seen += 1  # the planner is given something new
                text = f"reshape {msg.command} to {msg.name} from plan {msg.base[:12]}"
                self.emit("/log", fg.LOG, fg.log(t_ns, fg.INFO, "operator", text), t_ns)
        elif isinstance(msg, ContactMsg):
            other = f"robot {msg.b}" if msg.b >= 0 else "an obstacle or a wall"
            text = f"CONTACT: robot {msg.a} touched {other} at t_sim {msg.t_sim:.2f} s"
            self.emit("/log", fg.LOG, fg.log(t_ns, fg.WARNING, "world", text), t_ns)

    def _log(self, t_ns: int, level: int, rid: int, text: str) -> None:
        self.emit("/log", fg.LOG, fg.log(t_ns, level, f"robot {rid}", text), t_ns)

    def _note(self, t_ns: int, level: int, text: str) -> None:
        self.emit("/log", fg.LOG, fg.log(t_ns, level, RECORDER, text), t_ns)

    def colour(self, rid: int) -> tuple[float, float, float]:
        k = self.order.index(rid) if rid in self.order else rid
        return PALETTE[k % len(PALETTE)]

    def _status(self, msg: StatusMsg, t_ns: int) -> None:
        self.emit(f"/robots/{msg.sender}/status", STATUS, asdict(msg), t_ns)
        self.phase[msg.sender] = msg
        if msg.plan_digest:
            self.claimed.setdefault(msg.plan_digest, t_ns)
            state = (self.records_seen, len(self.starts), len(self.claimed))
            if msg.plan_digest != self.plan_drawn and state != self.plan_tried:
                self.plan_tried = state
                self._plan(quiet=True)  # drawn as soon as it is known, for the live view
        change = (msg.phase, msg.wave, msg.error)
        if self.changes.get(msg.sender) == change:
            return
        self.changes[msg.sender] = change
        text = msg.phase + (f" (wave {msg.wave})" if msg.wave >= 0 else "")
        if msg.error:
            text += f": {msg.error}"
        elif msg.detail:
            text += f": {msg.detail}"
        if msg.check_parent >= 0:
            text += (
                f"; own check of parent {msg.check_parent}: "
                f"r_d {msg.r_d:+.1%}, r_phi {msg.r_phi:+.1%}"
            )
        failed = msg.phase == "failed" or bool(msg.error)
        self._log(t_ns, fg.ERROR if failed else fg.INFO, msg.sender, text)

    def _camera(self, key: str, msg: CameraMsg, t_ns: int) -> None:
        """A robot's camera frame as an image and its detections as annotations."""
        rid = msg.robot
        if id_from_key(key) != rid:  # signed by the key's owner, but about another robot
            raise ValueError(f"camera frame of robot {rid} on {key}")
        image = fg.compressed_image(t_ns, f"nao{rid}/camera", msg.jpeg, "jpeg")
        self.emit(f"/nao/{rid}/camera", fg.COMPRESSED_IMAGE, image, t_ns)
        c = fg.colour(self.colour(rid))
        boxes = [fg.box_annotation(t_ns, *d.box, c) for d in msg.detections]
        labels = [
            fg.text_annotation(t_ns, d.box[0], max(0, d.box[1] - 9), f"#{d.id} {d.d:.2f} m", c)
            for d in msg.detections
        ]
        white = fg.colour((1.0, 1.0, 1.0))
        head = f"nao {rid} yaw {math.degrees(msg.yaw):+.0f}°"
        labels.insert(0, fg.text_annotation(t_ns, 2, max(0, msg.height - 10), head, white))
        marks = fg.image_annotations(boxes, labels)
        self.emit(f"/nao/{rid}/camera/annotations", fg.IMAGE_ANNOTATIONS, marks, t_ns)

    def _truth(self, msg: TruthPosesMsg, t_ns: int) -> None:
        poses = {int(p[0]): (float(p[1]), float(p[2]), float(p[3])) for p in msg.poses}
        first = not self.starts
        for rid in sorted(poses):
            self.starts.setdefault(rid, poses[rid])
        if first:
            self.order = sorted(poses)
            self._world_obstacles(t_ns)
        robots = [self._robot(t_ns, rid, *poses[rid]) for rid in sorted(poses)]
        self.emit("/scene", fg.SCENE_UPDATE, fg.scene_update(robots), t_ns)
        for rid in sorted(poses):
            x, y, h = poses[rid]
            tf = fg.frame_transform(t_ns, "world", f"robot/{rid}", x, y, h)
            self.emit("/tf", fg.FRAME_TRANSFORM, tf, t_ns)

    def _robot(self, t_ns: int, rid: int, x: float, y: float, h: float) -> JSON:
        rgb = self.colour(rid)
        status = self.phase.get(rid)
        label = str(rid)
        if status is not None:
            label += f" {status.phase}" + (f" w{status.wave}" if status.wave >= 0 else "")
        body = fg.cylinder(
            fg.pose(x, y, HEIGHT / 2, h), 2 * FOOTPRINT_RADIUS, HEIGHT, fg.colour(rgb, 0.9)
        )
        nose = fg.arrow(fg.pose(x, y, 0.75 * HEIGHT, h), 0.35, fg.colour(rgb))
        tag = fg.text(fg.pose(x, y, HEIGHT + 0.15), label, fg.colour(rgb))
        return fg.entity(t_ns, f"robot/{rid}", cylinders=[body], arrows=[nose], texts=[tag])

    def _world_obstacles(self, t_ns: int) -> None:
        obstacles = self.obstacles
        if obstacles is None and self.scenario is not None:
            try:
                st = self.scenario.stat()
            except FileNotFoundError:
                return  # no scenario file: the world generated its own, without obstacles
            if st.st_mtime_ns < self.since_ns - MTIME_SLACK_NS:
                return  # an older run's file
            try:
                from sim import scenarios

                sc = scenarios.load(self.scenario)
            except (OSError, ValueError, KeyError, TypeError) as exc:
                self._note(t_ns, fg.WARNING, f"world obstacles not drawn: {reason(exc)}")
                return
            obstacles = [(o.x, o.y, o.radius) for o in sc.obstacles]
        if not obstacles:
            return
        rgba = fg.colour(OBSTACLE_RGBA[:3], OBSTACLE_RGBA[3])
        cyl = [
            fg.cylinder(fg.pose(x, y, OBSTACLE_HEIGHT / 2), 2 * r, OBSTACLE_HEIGHT, rgba)
            for x, y, r in obstacles
        ]
        update = fg.scene_update([fg.entity(t_ns, "obstacles", cylinders=cyl)])
        self.emit("/scene/obstacles", fg.SCENE_UPDATE, update, t_ns)

    # ----------------------------------------------------------------- the plan

    def finish(self) -> None:
        """Draw the plan (module docstring), or say in ``/log`` why it is not drawn; a plan
        already drawn while the run went on (:meth:`_status`) is not drawn again."""
        if not self.claimed:
            self._note(self.now_ns, fg.INFO, "no agent reported a plan: no plan drawn")
            return
        self._plan(quiet=False)

    def _plan(self, quiet: bool) -> None:
        """Draw the plan of the signed records when its digest is one an agent reported;
        ``quiet``: while the run goes on (the live view), a plan not (yet) drawable is
        not said in ``/log`` (the records of a re-search round may still come)."""
        t_ns = min(self.claimed.values())
        from agent.adapters import FormationAdapter

        fa = FormationAdapter()
        records = tuple(self.records[i] for i in sorted(self.records))
        try:
            plans = self._plans(fa, records)
        except (ValueError, KeyError, IndexError, ArithmeticError) as exc:
            if not quiet:
                self._note(t_ns, fg.WARNING, f"plan not drawn: {reason(exc)}")
            return
        first = plans[0]
        known = [p for p in plans if p.digest in self.claimed]
        if not known:
            if quiet:
                return
            given = ", ".join(p.digest[:12] for p in plans)
            reported = ", ".join(sorted(d[:12] for d in self.claimed))
            self._note(
                t_ns,
                fg.WARNING,
                f"plan not drawn: the signed records give plan {given}, the agents "
                f"reported {reported} (other planning parameters than the recorder's?)",
            )
            return
        plan = max(known, key=lambda p: self.claimed[p.digest])  # the newest reported
        if plan.digest == self.plan_drawn:
            return
        t_ns = self.claimed[plan.digest]
        try:  # the first plan starts where the robots stood (a plan from the circle: on it)
            frame = common_frame_pose({r.robot_id: r.start for r in first.robots}, self.starts)
        except ValueError as exc:
            if not quiet:
                self._note(t_ns, fg.WARNING, f"plan not drawn: {reason(exc)}")
            return
        x, y, h = frame
        turn = h - math.pi / 2
        self.emit(
            "/tf", fg.FRAME_TRANSFORM, fg.frame_transform(t_ns, "world", "common", x, y, turn), t_ns
        )
        axis = fa.axis_angle(plan) + turn
        ents = [self._plan_robot(t_ns, plan, rp, frame, axis) for rp in plan.robots]
        links = []
        for rp in plan.robots:
            if int(rp.parent) >= 0:
                links += [
                    (*to_world(rp.target, frame), 0.03),
                    (*to_world(plan.robot(int(rp.parent)).target, frame), 0.03),
                ]
        if links:
            ents.append(
                fg.entity(
                    t_ns, "plan/links", lines=[fg.line(links, fg.colour(GREY), 0.02, "LINE_LIST")]
                )
            )
        seen = [to_world(o, frame) for o in plan.obstacles]
        if seen:
            rgba = fg.colour(OBSTACLE_RGBA[:3], 0.3)
            cyl = [
                fg.cylinder(fg.pose(ox, oy, 0.01), 2 * self.params.radius, 0.02, rgba)
                for ox, oy in seen
            ]
            ents.append(fg.entity(t_ns, "plan/obstacles", cylinders=cyl))
        self.emit("/scene/plan", fg.SCENE_UPDATE, fg.scene_update(ents, clear_at=t_ns), t_ns)
        self.plan_drawn = str(plan.digest)
        self._note(
            t_ns,
            fg.INFO,
            f"plan {plan.digest[:12]} drawn: leader {plan.leader}, frame robot {plan.frame_robot}, "
            f"{len(plan.waves)} waves, excluded {list(plan.excluded)}",
        )

    def _plans(self, fa: Any, records: tuple[NeighborRecordMsg, ...]) -> list[Plan]:
        """The plans the fleet may report from ``records``: the plan of ``params``, and with
        the orientation ``cp`` also the formation's from its circle (AUV III.B.2.a)."""
        from agent.core.formation.reshape import from_circle

        first = fa.plan(records, self.params)
        plans = [first]
        if self.params.orientation == "cp" and len(first.robots) > 1:
            plans.append(from_circle(first, self.params))
        return plans + self._transitions(plans)

    def _transitions(self, plans: list[Plan]) -> list[Plan]:
        """The plans of the reshape commands seen, each from the plan it names (one of
        ``plans`` or an earlier transition), in command order; a command that names no
        such plan, or that the planner refuses, gives none (the agents refuse it too)."""
        from agent.core.formation.reshape import command_shape, transition_plan

        by_digest = {str(p.digest): p for p in plans}
        out: list[Plan] = []
        for number in sorted(self.commands):
            cmd = self.commands[number]
            held = by_digest.get(cmd.base)
            if held is None:
                continue
            try:
                shape = command_shape(cmd.name, cmd.rule, cmd.orient, cmd.slots, cmd.shape_digest)
                plan = transition_plan(held, shape, self.params)
            except ValueError:
                continue
            by_digest[str(plan.digest)] = plan
            out.append(plan)
        return out

    def _plan_robot(
        self, t_ns: int, plan: Plan, rp: RobotPlan, frame: tuple[float, float, float], axis: float
    ) -> JSON:
        rgb = self.colour(int(rp.robot_id))
        tx, ty = to_world(rp.target, frame)
        disc = fg.cylinder(fg.pose(tx, ty, 0.01), 2 * FOOTPRINT_RADIUS, 0.02, fg.colour(rgb, 0.35))
        facing = fg.arrow(fg.pose(tx, ty, 0.03, axis), 0.3, fg.colour(rgb, 0.6))
        role = "leader" if int(rp.robot_id) == int(plan.leader) else f"parent {rp.parent}"
        tag = fg.text(
            fg.pose(tx, ty, 0.2), f"{rp.robot_id} target ({role})", fg.colour(rgb, 0.8), 0.08
        )
        path = [(*to_world(p, frame), 0.02) for p in rp.path()]
        walk = fg.line(path, fg.colour(rgb, 0.8), 0.02, "LINE_STRIP")
        return fg.entity(
            t_ns,
            f"plan/robot/{rp.robot_id}",
            cylinders=[disc],
            arrows=[facing],
            texts=[tag],
            lines=[walk],
        )
