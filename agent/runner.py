"""The phase machine of one agent (DESIGN.md §1; NAO paper 5.2.2 (iii) steps 1–7).

SEARCH   sweep the head over [-119.5°, 119.5°] at θ = 0, turn to θ = 180° with the
         rotation control, sweep again (5.2.2 (iii) step 2); complete the circle to
         calibrate the compass against the first image (an addition).
LOCALISE detections → fixed frame (eqs. 7–8) with the compass-estimated heading,
         merged across images.
EXCHANGE/AGREE publish the record, collect every member's, move only once every live
         member published the same digest (agent/exchange.py).
PLAN     formation core on the agreed records (4.1.2–4.2): identical on every agent.
WAIT     for every robot of earlier waves to hold (leader first, 5.2.2 step 7).
MOVE     rotation control to face the goal, distance control in 20 cm steps with the
         heading corrected after each (4.2, 5.2.2), then turn to the pyramid axis.
HOLD     arrived (status ``hold``); once the whole fleet has arrived and the parent is
         ``done`` (``march``), look at the parent and step by the measured offset error
         (an addition, see :meth:`Runner.correct`), then ``done`` and stay until all are.
MARCH    with a route (issue #13, agent/march.py): after the correction, ``march`` and
         wait until every member is marching; the leader walks the route, followers
         keep station on their parent by vision; then ``done`` as above.

Heading belief: the agent's heading in its fixed frame starts at pi/2 (every robot
faces north at the start, 4.1.1) and changes only by visual-compass measurements of its
own turns and steps (eq. 2), or, when the compass fails, by the turn it commanded.
Position belief: (0, 0) in the fixed frame at the start, dead-reckoned from the
commanded steps along the believed heading. Agents never read ground truth.
"""

from __future__ import annotations

import contextlib
import logging
import math
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from agent.bus import Bus, Event
from agent.config import AgentConfig
from agent.control import (
    PAPER_GAINS,
    STEP_GAINS,
    PidGains,
    RotationControl,
    advance,
    next_leg,
    wrap_pi,
)
from agent.exchange import Agreement, Decision, Grace, params_digest
from agent.formation.plan import Plan
from agent.journal import Journal
from agent.march import Marcher, MarchHalt
from agent.nao import HEAD_YAW_LIMIT
from agent.perception.detector import Detection
from agent.protocol import (
    KEY_ALIVE_ALL,
    KEY_DIGEST_ALL,
    KEY_RECORD_ALL,
    KEY_STATUS_ALL,
    DigestMsg,
    NeighborRecordMsg,
    RecordSetReply,
    StatusMsg,
    id_from_key,
    key_alive,
    key_digest,
    key_record,
    key_records,
    key_status,
    reason,
)
from agent.seams import Body, BodyError, Formation, Frame, MotionResult, Perception, Sightings

log = logging.getLogger("agent.runner")

NORTH = math.pi / 2
ARRIVED = ("hold", "march", "done", "failed")  # phases of a member that has arrived
STATUS_MIN_INTERVAL = 3.0  # s between progress statuses of the same phase
HEARTBEAT = 3.0  # s between statuses while waiting


class AgentFailure(RuntimeError):
    """A reason to stop safely (status ``failed``); the text is the reason."""


@dataclass
class Peer:
    alive: bool = False
    phase: str = ""
    detail: str = ""
    wave: int = -1
    plan_digest: str = ""
    seen_alive: bool = False


@dataclass
class Timeline:
    """Wall and sim time at each phase start (for the report)."""

    marks: list[tuple[str, float, float]] = field(default_factory=list)

    def mark(self, phase: str, t_sim: float) -> None:
        self.marks.append((phase, time.monotonic(), t_sim))


class Runner:
    """Drives one robot through the phases; :meth:`run` returns the exit code.

    It depends only on the seams of :mod:`agent.seams`: a :class:`~agent.seams.Body`
    (zenoh world, NAOqi or in-process world), a :class:`~agent.seams.Perception` and a
    :class:`~agent.seams.Formation`; the bus carries the exchange between agents.
    """

    def __init__(
        self,
        bus: Bus,
        body: Body,
        config: AgentConfig,
        perception: Perception,
        formation: Formation,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if body.robot_id != config.robot_id:
            raise ValueError(f"robot {body.robot_id} driven with config for {config.robot_id}")
        self.bus = bus
        self.body = body
        self.cfg = config
        self.me = config.robot_id
        self.clock = clock
        self.perception = perception
        self.formation = formation
        self.heading = NORTH
        self.position = np.zeros(2)
        self.phase = "start"
        self.peers: dict[int, Peer] = {}
        self.grace = Grace(config.member_grace)  # a vanished token is gone only after it
        self.early_records: dict[int, NeighborRecordMsg] = {}
        self.epochs: dict[int, int] = {}  # newest session (epoch) heard per sender
        self.agreed_epochs: dict[int, int] = {}  # the sessions the agreement was made with
        self.early_digests: dict[int, DigestMsg] = {}
        self.agreement: Agreement | None = None
        self._plan: Plan | None = None
        self.plan_digest = ""
        self.wave = -1
        self.record_round = 0
        self.timeline = Timeline()
        self._last_status = -math.inf
        self._last_frame: Frame | None = None
        self.compass_failures = 0
        self.compass_uses = 0
        self.compass_gain = 1.0
        self.final_heading = NORTH
        # issue #9: the durable journal (None: not kept), what it holds, what we serve
        self.journal: Journal | None = None
        self.own_record: NeighborRecordMsg | None = None
        self.leg = 0  # the move's current leg
        self._served: RecordSetReply | None = None

    # ================================================================= plumbing

    @property
    def plan(self) -> Plan:
        """The agreed plan (after :meth:`make_plan`)."""
        if self._plan is None:
            raise AgentFailure("no plan yet")
        return self._plan

    @plan.setter
    def plan(self, plan: Plan) -> None:
        self._plan = plan

    def start_bus(self) -> None:
        for key in (KEY_RECORD_ALL, KEY_DIGEST_ALL, KEY_STATUS_ALL):
            self.bus.subscribe(key)
        self.bus.watch_alive(KEY_ALIVE_ALL)
        self.bus.declare_alive(key_alive(self.me))
        from agent.resume import answer

        self.bus.serve(key_records(self.me), lambda req: answer(self._served, req))

    def _journal(self, command: str = "", value: float = 0.0) -> None:
        """Write the journal (issue #9), before ``command`` is sent; a failing disk is
        logged and the journal given up, never fatal."""
        if self.journal is None:
            return
        from agent.resume import journal_state

        try:
            self.journal.save(journal_state(self, command, value))
        except (OSError, ValueError) as exc:
            log.error("journal write failed, journal given up: %s", reason(exc))
            self.journal = None

    def status(
        self,
        phase: str,
        progress: float = 0.0,
        detail: str = "",
        error: str = "",
        force: bool = False,
    ) -> None:
        now = self.clock()
        changed = phase != self.phase
        if changed:
            self.timeline.mark(phase, self.body.t_sim)
        self.phase = phase
        if changed:
            self._journal()
        if not (changed or force or now - self._last_status >= STATUS_MIN_INTERVAL):
            return
        self._last_status = now
        msg = StatusMsg(
            sender=self.me,
            phase=phase,
            progress=min(1.0, max(0.0, progress)),
            detail=detail[:500],
            plan_digest=self.plan_digest,
            wave=self.wave,
            error=error[:500],
            t_sim=self.body.t_sim,
            bytes_sent=self.bus.stats.total_published,
        )
        self.bus.publish(key_status(self.me), msg, "status")

    def pump(self, timeout: float = 0.0) -> None:
        """Handle what arrived; (re-)publish what the agreement says is due."""
        for ev in self.bus.drain(timeout):
            try:
                self._handle(ev)
            except Exception as exc:  # one bad event is counted and skipped, never fatal
                self.bus.guard.reject(f"event on {ev.key}", exc)
        self._expire_members()
        agr = self.agreement
        if agr is not None:
            now = self.clock()
            due = agr.due(now)
            for what in due:
                if what == "record":
                    self.bus.publish(key_record(self.me), agr.records[self.me], "record")
                else:
                    self.bus.publish(
                        key_digest(self.me), agr.digest_msg(self.record_round), "digest"
                    )
            agr.sent(due, now)

    def _handle(self, ev: Event) -> None:
        now = self.clock()
        agr = self.agreement
        if ev.kind in ("alive", "gone"):
            peer = self.peers.setdefault(ev.robot_id, Peer())
            self.grace.token(ev.robot_id, ev.kind == "alive", now)
            if ev.kind == "alive":  # a vanished token counts as gone in _expire_members
                peer.alive = peer.seen_alive = True
                if agr is not None and ev.robot_id != self.me:
                    agr.member_joined(ev.robot_id, now)
            return
        msg = ev.msg
        if not isinstance(msg, NeighborRecordMsg | DigestMsg | StatusMsg):
            return
        try:
            key_id = id_from_key(ev.key)
        except ValueError:
            key_id = None
        if key_id != msg.sender:
            log.warning(
                "dropped %s on %s: sender %s does not own the key", msg.TAG, ev.key, msg.sender
            )
            return
        if not self._current_session(ev, msg.sender):
            return
        self.grace.heard(msg.sender, now)  # a member's publication is a heartbeat
        if isinstance(msg, NeighborRecordMsg):
            if agr is not None:
                agr.on_record(msg, now)
            elif msg.sender != self.me and self._member(msg.sender):
                old = self.early_records.get(msg.sender)
                if old is None or old.round <= msg.round:
                    self.early_records[msg.sender] = msg
        elif isinstance(msg, DigestMsg):
            if agr is not None:
                agr.on_digest(msg, now)
            elif msg.sender != self.me and self._member(msg.sender):
                self.early_digests[msg.sender] = msg
        elif isinstance(msg, StatusMsg):
            member = self.peers.get(msg.sender)
            if msg.sender == self.me or member is None or not member.seen_alive:
                return  # per-sender state only for members (their token came first)
            member.phase, member.wave, member.plan_digest = msg.phase, msg.wave, msg.plan_digest
            member.detail = msg.detail
            if agr is not None:
                agr.on_peer_phase(msg.sender, msg.phase)

    def _expire_members(self) -> None:
        """Members whose token vanished and who stayed silent for the grace period are gone."""
        now = self.clock()
        for rid in self.grace.expired(now):
            peer = self.peers.get(rid)
            if peer is None or not peer.alive:
                continue
            peer.alive = False
            log.warning("robot %d is gone (token lost, silent for %g s)", rid, self.grace.grace)
            if self.agreement is not None and rid != self.me:
                self.agreement.member_left(rid, now)

    def _proves_agreement(self, msg: object) -> bool:
        """Whether ``msg`` shows the record-set digest (or plan digest) we agreed on."""
        agr = self.agreement
        if agr is None or not agr.agreed:
            return False
        if isinstance(msg, DigestMsg):
            members, digest = agr.digest()
            return msg.digest == digest and msg.members == members and msg.params == agr.params
        return (
            isinstance(msg, StatusMsg)
            and bool(self.plan_digest)
            and (msg.plan_digest == self.plan_digest)
        )

    def _member(self, rid: int) -> bool:
        peer = self.peers.get(rid)
        return peer is not None and peer.alive

    def _current_session(self, ev: Event, sender: int) -> bool:
        """Whether ``ev`` comes from the member's current session (DESIGN.md §8).

        Secure buses tag each message with its signer's epoch (the sending process's
        start). A message from an older session of a member than one already heard is
        stale (a replay, or a process since replaced); once the fleet has agreed, only
        the session whose record was agreed counts. Insecure buses carry no epoch.
        """
        if ev.epoch < 0:
            return True
        pinned = self.agreed_epochs.get(sender)
        if pinned is not None:
            if ev.epoch > pinned and self._proves_agreement(ev.msg):
                # a member restarted after agreeing (issue #9): its new session counts
                log.info("robot %d resumed in a new session with the agreed digest", sender)
                self.agreed_epochs[sender] = self.epochs[sender] = ev.epoch
            return ev.epoch == self.agreed_epochs[sender]
        if ev.epoch < self.epochs.get(sender, -1):
            return False
        self.epochs[sender] = ev.epoch
        return True

    # ================================================================= motion

    def look(self, yaw: float = 0.0) -> Frame:
        frame = self.body.camera(yaw)
        self.pump()
        return frame

    def rotate(self, angle: float, gains: PidGains = PAPER_GAINS, label: str = "") -> float:
        """Turn the body by ``angle`` (rad, + CCW) with the rotation control (5.2.2 (1)).

        Returns the rotation completed according to the compass (rad)."""
        rc = RotationControl(angle, gains=gains, tolerance=self.cfg.rotation_tolerance)
        before = self._last_frame if self._last_frame is not None else self.look(0.0)
        while not (rc.done or rc.exhausted):
            u = rc.next_step()
            self._journal("turn", u)
            rep = self.body.turn(u)
            self.pump()
            after = self.look(0.0)
            measured = self._compass(before, after, u)
            rc.record(measured)
            self.heading = wrap_pi(self.heading + measured)
            log.debug(
                "turn t_sim %.2f cmd %+.2f° measured %+.2f° heading %.2f°",
                rep.t_sim, math.degrees(u), math.degrees(measured), math.degrees(self.heading),
            )  # fmt: skip
            before = after
            if label:
                self.status(self.phase, detail=f"{label}: {math.degrees(rc.error):+.1f}° to go")
            if rep.status == "contact":
                log.warning("contact while turning")
        self._last_frame = before
        return rc.completed

    def _compass(
        self, before: Frame, after: Frame, commanded: float, walking: bool = False
    ) -> float:
        """The rotation between two head-yaw-0 frames; the command when the compass fails.

        ``walking``: the frames are 20 cm apart, so only the central band of the image
        is matched (see :meth:`agent.adapters.PerceptionAdapter.measure_walk`)."""
        if walking:
            res = self.perception.measure_walk(before.image, after.image)
        else:
            res = self.perception.measure_turn(before.image, after.image)
        self.compass_uses += 1
        if not res.ok:
            self.compass_failures += 1
            log.warning(
                "compass failed (%s): assuming the %s %+.1f°",
                res.reason, "drift" if walking else "command",
                math.degrees(commanded),
            )  # fmt: skip
            return commanded
        dtheta = float(res.dtheta) * self.compass_gain
        # A measurement far from the command is more likely a mismatch than a fall.
        # (a step's drift reaches ~9° in the simulator: allow 20° when walking)
        limit = math.radians(20.0 if walking else 10.0)
        if abs(dtheta - commanded) > max(limit, 0.6 * abs(commanded)):
            self.compass_failures += 1
            log.warning(
                "compass %+.1f° implausible against %+.1f°: ignored",
                math.degrees(dtheta), math.degrees(commanded),
            )  # fmt: skip
            return commanded
        return dtheta

    def walk_to(
        self, goal: np.ndarray, progress: Callable[[float], None], backward_within: float = 0.0
    ) -> None:
        """Distance control to ``goal`` (fixed frame, m) from the dead-reckoned position."""
        total = float(np.hypot(*(goal - self.position))) or 1.0
        for _ in range(200):
            leg = next_leg(self.position, self.heading, goal, backward_within=backward_within)
            if leg is None:
                return
            if abs(leg.turn) > self.cfg.rotation_tolerance:
                self.rotate(
                    leg.turn, STEP_GAINS if abs(leg.turn) < math.radians(15) else PAPER_GAINS
                )
            self.walk_step(leg.walk)
            progress(1.0 - max(0.0, leg.remaining - abs(leg.walk)) / total)
        raise AgentFailure("distance control did not converge in 200 steps")

    def walk_step(self, distance: float) -> MotionResult:
        """One straight step, the compass's drift and dead reckoning (4.2, eq. 2)."""
        before = self._last_frame if self._last_frame is not None else self.look(0.0)
        h0 = self.heading
        self._journal("walk", distance)
        rep = self.body.walk(distance)
        self.pump()
        after = self.look(0.0)
        drift = self._compass(before, after, 0.0, walking=True)
        self.heading = wrap_pi(self.heading + drift)
        self._last_frame = after
        self.position = advance(self.position, h0, self.heading, distance)
        log.debug(
            "walk t_sim %.2f %.3f m drift %+.2f° heading %.2f° position %s",
            rep.t_sim, distance, math.degrees(drift), math.degrees(self.heading),
            self.position.round(3).tolist(),
        )  # fmt: skip
        if rep.status == "contact":
            raise AgentFailure(
                f"contact while walking at believed {self.position.round(2).tolist()}"
            )
        return rep

    # ================================================================= phases

    def search(self) -> list[Sightings]:
        """Sweeps at θ = 0 and θ = 180° (5.2.2 (iii)); returns fixed-frame sightings.

        Addition to the paper: after the second sweep the robot completes the circle
        back to θ = 0. The yaw-0 image taken at the start *defines* the fixed frame, so
        the compass between it and the image after the full circle gives the absolute
        residual r; the compass gain is then (2π + r) / (sum of compass steps), which
        removes the compass's scale error (parallax of the off-axis camera) from the
        θ = 180° sweep and from every later turn, and the heading is known absolutely.
        """
        self.status("search", 0.0, "sweep at θ = 0°")
        n = 2 * len(self.cfg.search_yaws)
        raw: list[tuple[int, list[Detection]]] = []
        done = 0
        origin: Frame | None = None
        turned = [0.0, 0.0]
        for sweep in range(2):
            if sweep == 1:
                turned[0] = self.rotate(math.pi, PAPER_GAINS, "turn to θ = 180°")
            for yaw in self.cfg.search_yaws:
                frame = self.look(yaw)
                if abs(yaw) < 1e-9:
                    self._last_frame = frame
                    if sweep == 0:
                        origin = frame
                raw.append((sweep, self.perception.detect(frame.image, yaw)))
                done += 1
                self.status(
                    "search", done / n, f"θ = {180 * sweep}°, head {math.degrees(yaw):+.0f}°"
                )
            # the last image of the sweep was not at yaw 0: refresh the compass reference
            self._last_frame = self.look(0.0)
            if origin is None:
                origin = self._last_frame
            if sweep == 0 and self.journal is not None:  # the view that defines the fixed frame
                try:
                    self.journal.save_reference(origin.image)
                except (OSError, ValueError) as exc:
                    log.error("reference view not journaled: %s", reason(exc))
        heading_180 = self.heading
        turned[1] = self.rotate(math.pi, PAPER_GAINS, "complete the circle to θ = 0°")
        assert origin is not None and self._last_frame is not None
        self._calibrate(origin, self._last_frame, turned)
        if self.compass_gain != 1.0:
            heading_180 = wrap_pi(NORTH + self.compass_gain * turned[0])
        return [
            self.perception.to_fixed(dets, NORTH if sweep == 0 else heading_180)
            for sweep, dets in raw
        ]

    def _calibrate(self, origin: Frame, final: Frame, turned: list[float]) -> None:
        """Compass gain and absolute heading from the full circle (see :meth:`search`)."""
        res = self.perception.measure_turn(origin.image, final.image)
        total = turned[0] + turned[1]
        if not res.ok or total < math.pi:
            log.warning("compass calibration skipped: %s", res.reason if not res.ok else "no turn")
            return
        r = float(res.dtheta)
        gain = (2.0 * math.pi + r) / total
        if not 0.9 <= gain <= 1.1:
            log.warning("compass gain %.4f implausible: kept 1.0", gain)
            return
        self.compass_gain = gain
        self.heading = wrap_pi(NORTH + r)
        log.info(
            "compass calibrated over the circle: gain %.4f, residual %+.2f°", gain, math.degrees(r)
        )

    def localise(self, sightings: list[Sightings]) -> NeighborRecordMsg:
        self.status("localise", 0.0)
        pts, ori, conf = self.perception.merge(sightings)
        rec = NeighborRecordMsg(
            sender=self.me,
            round=self.record_round,
            neighbours=tuple((float(x), float(y)) for x, y in pts),
            orientations=tuple(float(o) for o in ori),
            confidences=tuple(float(c) for c in conf),
        )
        self.own_record = rec
        self.status("localise", 1.0, f"{len(pts)} neighbours")
        return rec

    def agree(self, record: NeighborRecordMsg) -> Decision:
        now = self.clock()
        agr = Agreement(
            self.me,
            record,
            now,
            fleet_size=self.cfg.fleet_size,
            timeout=self.cfg.timeout,
            settle=self.cfg.settle,
            backoff_max=self.cfg.backoff_max,
            params=params_digest(self.cfg.agreed_params()),
        )
        for rid, peer in sorted(self.peers.items()):
            if rid != self.me and peer.alive:
                agr.member_joined(rid, now)
            elif rid != self.me and peer.seen_alive:
                # it was a member and left while we searched: that is a departure too
                agr.member_joined(rid, now)
                agr.member_left(rid, now)
        for msg in self.early_records.values():
            agr.on_record(msg, now)
        for dmsg in self.early_digests.values():
            agr.on_digest(dmsg, now)
        for rid, peer in self.peers.items():
            agr.on_peer_phase(rid, peer.phase)
        self.agreement = agr
        self.status("exchange", 0.0, "publishing record")
        while True:
            self.pump(0.05)
            d = agr.decide(self.clock())
            if d.kind != "wait":
                return d
            n = max(1, len(agr.live))
            held = len(agr.held_members())
            agreeing = n - len(agr.disagreeing())
            phase = "exchange" if agr.missing_records() else "agree"
            self.status(phase, (held + agreeing) / (2 * n), d.reason)

    def make_plan(self, decision: Decision) -> Plan:
        self.status("plan", 0.0, decision.reason)
        try:
            plan = self.formation.plan(decision.records, self.cfg.d_e, self.cfg.phi_e)
        except ValueError as exc:
            raise AgentFailure(f"planning failed on the agreed records: {exc}") from None
        self.plan = plan
        self.plan_digest = str(plan.digest)
        from agent.resume import record_set

        self._served = record_set(self.me, decision)
        members = {int(r) for r in self.formation.members(plan)}
        self.agreed_epochs = {r: e for r, e in self.epochs.items() if r in members}
        rp = plan.robot(self.me)
        self.wave = int(rp.wave)
        self.status("plan", 1.0, f"wave {self.wave}, leader {plan.leader}", force=True)
        return plan

    def wait_for_earlier_waves(self) -> None:
        """Start once every robot of this robot's ``after`` list holds its slot (the plan's
        execution rule, ``agent/formation/execution.py``; the leader's list is empty)."""
        plan = self.plan
        members = set(self.formation.members(plan))
        earlier = sorted(
            int(i) for i in plan.robot(self.me).after if int(i) in members and int(i) != self.me
        )
        deadline = self.clock() + self.cfg.wave_timeout
        while True:
            self.pump(0.1)
            pending = []
            for i in earlier:
                peer = self.peers.get(i, Peer())
                if peer.phase in ("hold", "march", "done"):
                    continue
                if peer.seen_alive and not peer.alive:
                    raise AgentFailure(
                        f"robot {i} of wave {plan.robot(i).wave} left before holding"
                    )
                if peer.phase == "failed":
                    raise AgentFailure(f"robot {i} of wave {plan.robot(i).wave} failed")
                pending.append(i)
            if not pending:
                return
            if self.clock() > deadline:
                raise AgentFailure(f"robots {pending} of earlier waves did not hold in time")
            self.status("wait", 0.0, f"waiting for wave(s) of {pending}")

    def move(self) -> None:
        plan = self.plan
        self._last_frame = None  # others moved meanwhile: a fresh compass reference
        goals, final_heading = self.formation.goals(plan, self.me)
        self.final_heading = final_heading
        self.status("move", 0.0, f"{len(goals)} leg(s)")
        n = len(goals)
        for k, goal in enumerate(goals):
            if k < self.leg:
                continue  # walked before a restart (issue #9)
            self.leg = k

            def progress(p: float, k: int = k) -> None:
                self.status("move", (k + p) / n, f"leg {k + 1}/{n}")

            self.walk_to(goal, progress)
        self.rotate(wrap_pi(final_heading - self.heading), PAPER_GAINS, "turn to pyramid axis")

    def _all_arrived(self) -> bool:
        members = self.agreement.held_members() if self.agreement else ()
        for i in members:
            peer = self.peers.get(i, Peer())
            if i != self.me and peer.alive and peer.phase not in ARRIVED:
                return False
        return True

    def correct(self) -> None:
        """Visual alignment to the parent, once everyone has arrived (an addition).

        The papers walk the plan open-loop; the residual error is dominated by the
        distance estimates of the search (~10 % at 1.2 m, better at d_e). The pyramid
        is defined by parent–child offsets (AUV II: robots follow the robot in front
        by visual servoing), so once the whole fleet has arrived and the parent has
        finished its own correction (``done``), the child looks at where the plan puts
        its parent, measures it and steps by the difference. Corrections larger than
        ``max_correction`` (a wrong match) or below 3 cm are not walked.
        """
        plan = self.plan
        rp = plan.robot(self.me)
        parent = int(rp.parent)
        if parent < 0 or not self.cfg.correct:
            return
        deadline = self.clock() + self.cfg.wave_timeout
        while True:
            self.pump(0.1)
            peer = self.peers.get(parent, Peer())
            if peer.phase == "failed" or (peer.seen_alive and not peer.alive):
                log.warning("parent %d is gone: no correction", parent)
                return
            if peer.phase in ("done", "march") and self._all_arrived():
                break
            if self.clock() > deadline:
                log.warning("parent %d did not finish in time: no correction", parent)
                return
            self.status("hold", 0.5, f"arrived; waiting for parent {parent}")
        expected = np.asarray(plan.robot(parent).target, dtype=np.float64) - np.asarray(
            rp.target, dtype=np.float64
        )
        for attempt in range(2):
            bearing = math.atan2(float(expected[1]), float(expected[0]))
            yaw = float(np.clip(wrap_pi(bearing - self.heading), -HEAD_YAW_LIMIT, HEAD_YAW_LIMIT))
            frame = self.look(yaw)
            dets = self.perception.detect(frame.image, yaw)
            pts, _, _ = self.perception.to_fixed(dets, self.heading)
            if len(pts) == 0:
                log.warning("correction: parent %d not seen", parent)
                return
            k = int(np.argmin(np.hypot(*(pts - expected).T)))
            err = pts[k] - expected
            size = float(np.hypot(*err))
            log.info(
                "correction %d: parent %d seen at %s, planned %s, step %.3f m",
                attempt + 1, parent, pts[k].round(3).tolist(), expected.round(3).tolist(), size,
            )  # fmt: skip
            if size < 0.03:
                break
            if size > self.cfg.max_correction:
                log.warning("correction of %.2f m is implausible: not walked", size)
                break
            self.status("hold", 0.75, f"correcting {size:.2f} m towards parent {parent}")
            self._last_frame = None
            self.walk_to(self.position + err, lambda p: None, backward_within=0.5)
            self.rotate(wrap_pi(self.final_heading - self.heading), PAPER_GAINS)

    def hold(self) -> None:
        """Arrived: correct against the parent, march if there is a route, report
        ``done`` and stay until all are."""
        self.status(
            "hold", 0.5, f"arrived at believed {self.position.round(2).tolist()}", force=True
        )
        self.correct()
        if self.cfg.march is not None:
            self.status("march", 0.0, "formation held; waiting for the fleet", force=True)
            self._wait_all(("march", "done", "failed"), "march", "waiting for")
            failed = [i for i, p in self.peers.items() if p.phase == "failed"]
            if failed:
                raise AgentFailure(f"not marching: robot(s) {sorted(failed)} failed")
            self.status("march", 0.01, "marching", force=True)
            marcher = Marcher(self, self.cfg.march, self.final_heading)
            marcher.run()
            log.info(
                "march done at believed %s; worst seen |e_d| %.1f %%, |e_phi| %.1f°",
                self.position.round(2).tolist(), 100 * marcher.worst_range,
                math.degrees(marcher.worst_bearing),
            )  # fmt: skip
        self.finish()

    def finish(self) -> None:
        """``done``, and stay until every member is."""
        self.status("done", 1.0, "formation held", force=True)
        self._wait_all(("done", "failed"), "done", "formation held; waiting for")

    def _wait_all(self, phases: tuple[str, ...], mine: str, text: str) -> None:
        """Stay (heartbeats) until every live member is in ``phases`` (bounded)."""
        members = self.agreement.held_members() if self.agreement else ()
        deadline = self.clock() + self.cfg.wave_timeout
        while self.clock() < deadline:
            self.pump(0.2)
            waiting = [
                i
                for i in members
                if i != self.me
                and self.peers.get(i, Peer()).phase not in phases
                and self.peers.get(i, Peer()).alive
            ]
            if not waiting and (self.agreement is None or not self.agreement.due(self.clock())):
                return
            if self.clock() - self._last_status >= HEARTBEAT:
                self.status(mine, 1.0 if mine == "done" else 0.0, f"{text} {waiting}", force=True)
        if mine == "march":
            raise AgentFailure("the fleet did not get ready to march in time")

    # ================================================================= main

    def run(self) -> int:
        try:
            self.start_bus()
            stage, record = self.resume()
            if stage == "search":
                self.status("start", 0.0, "joined", force=True)
                record = self.localise(self.search())
            if stage in ("search", "agree"):
                assert record is not None
                decision = self.agree(record)
                if decision.kind != "agreed":
                    raise AgentFailure(decision.reason)
                self.make_plan(decision)
            if stage in ("search", "agree", "wait"):
                self.wait_for_earlier_waves()
            if stage in ("search", "agree", "wait", "move"):
                self.move()
            if stage == "done":
                self.finish()
            else:
                self.hold()
            return 0
        except (AgentFailure, MarchHalt, BodyError, ValueError) as exc:
            return self.fail(reason(exc))
        except Exception as exc:  # a bug or an input nobody foresaw: stop safely, never crash
            log.error(
                "robot %d: unexpected %s\n%s",
                self.me,
                reason(exc),
                "".join(traceback.format_tb(exc.__traceback__))[-2000:],
            )
            try:
                return self.fail(f"unexpected {reason(exc)}")
            except Exception as exc2:
                log.error("robot %d could not publish failed: %s", self.me, reason(exc2))
                return 1
        finally:
            with contextlib.suppress(BodyError):
                self.body.stop()

    def resume(self) -> tuple[str, NeighborRecordMsg | None]:
        """Where to start: ``search`` afresh, or what the journal says (agent/resume.py)."""
        if self.journal is None:
            return "search", None
        from agent import resume

        st = resume.load(self.journal)
        if st is None:
            return "search", None
        stage, record = resume.resume(self, st)
        log.info("robot %d resumes at %s (journaled phase %s)", self.me, stage, st.phase)
        return stage, record

    def fail(self, reason: str) -> int:
        """Stop safely: publish ``failed`` with ``reason``, let it reach the others; 1."""
        log.error("robot %d failed: %s", self.me, reason)
        self.status("failed", 0.0, error=reason, force=True)
        # let the failure status and any pending digest reach the others
        end = self.clock() + 1.0
        while self.clock() < end:
            self.pump(0.1)
        return 1


def report_unavailable(bus: Bus, robot_id: int, reason: str) -> int:
    """An agent that cannot run (perception or formation core missing) joins, publishes
    ``failed`` with ``reason`` so the fleet stops safely, and returns exit code 1."""
    log.error("robot %d cannot run: %s", robot_id, reason)
    bus.declare_alive(key_alive(robot_id))
    msg = StatusMsg(sender=robot_id, phase="failed", error=reason[:500])
    bus.publish(key_status(robot_id), msg, "status")
    bus.drain(1.0)
    return 1
