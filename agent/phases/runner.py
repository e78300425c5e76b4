"""The phase machine of one agent (docs/design.md §1, §8; NAO paper 5.2.2 (iii) steps 1–7).

::

    SEARCH ─► LOCALISE ─► EXCHANGE/AGREE ─► PLAN ─► WAIT ─► MOVE ─► HOLD ─► (MARCH) ─► DONE ─► (RESHAPE)
      ▲ re-search when the agreed set leaves a robot unseen │
      └─────────────────────────────────────────────────────┘
    RESUME: a restarted agent enters where its journal says (its run still going);
    FAIL: any phase stops safely. The journal's last record says how the run ended.

(Phases are :class:`~agent.phases.reporting.Phase` members, written as the strings
statuses and journals carry.)

SEARCH/LOCALISE  head sweeps at θ = 0 and θ = 180°, the compass calibrated by the sweeps'
                 overlapping views (the full circle as a fallback); detections into the
                 fixed frame, merged into this robot's record (agent/phases/search.py).
EXCHANGE/AGREE   publish the record, collect every member's, go on only once every live
                 member published the same digest (agent/phases/agreeing.py over
                 agent/core/agreement.py).
RE-SEARCH        when the agreed records leave robots outside the connected fleet, those
                 robots explore and every robot searches again (4.1.3 rule 2,
                 agent/phases/research.py); a new round is agreed.
PLAN/WAIT/MOVE   the formation core on the agreed records, identical on every agent; wait
                 for the earlier waves to hold; walk the legs in checked 20 cm steps
                 (agent/phases/waves.py, safe_steps.py, motion.py).
CIRCLE           with ``--orientation cp`` that plan is the circle pattern's circle: hold
                 it (fine-tuned on the centre robot unless ``--no-cp-tune``), then plan
                 the formation from it and walk it (agent/phases/transitions/circle_pattern.py).
HOLD/MARCH/DONE  correct against the parent, march the route if there is one, ``done``
                 and stay until all are (agent/phases/hold.py, march.py).
RESHAPE          with ``--reshape-wait``: listen for the operator's command, plan the
                 transition to its shape and walk it as every plan (PLAN, WAIT, MOVE,
                 HOLD, DONE; agent/phases/transitions/reshaping.py).

With ``--publish-camera`` (for viewers) the perception is wrapped by
agent/phases/camera_feed.py, which publishes thumbnails of the analysed frames for viewers.

The :class:`Runner` only composes the collaborators around one shared
:class:`~agent.phases.context.Context` (the typed roles between them are in
agent/phases/roles.py) and walks the phases in order; every wait in every phase hears
the fleet (agent/phases/membership.py). Crash recovery (RESUME, and the journal written
meanwhile) is handed in as a :class:`~agent.phases.roles.Recovery` built on the runner's
:class:`~agent.phases.roles.Crew` (agent/recovery/, wired by ``python -m agent
--state-dir``); without it every start is a fresh one (:class:`Fresh`).
"""

from __future__ import annotations

import contextlib
import logging
import time
import traceback
from collections.abc import Callable

from agent.body.base import Body, BodyError
from agent.config import AgentConfig
from agent.core.agreement import Decision
from agent.net.bus import Bus
from agent.phases.agreeing import Agreeing
from agent.phases.camera_feed import CameraFeed
from agent.phases.context import AgentFailure, Context
from agent.phases.hold import Hold
from agent.phases.march import MarchHalt
from agent.phases.membership import Membership
from agent.phases.motion import Motion
from agent.phases.reporting import NoJournal, Phase
from agent.phases.research import Research
from agent.phases.roles import Crew, Recovery
from agent.phases.safe_steps import SafeSteps
from agent.phases.search import Search
from agent.phases.transitions.circle_pattern import CirclePattern
from agent.phases.transitions.reshaping import Reshaping
from agent.phases.waves import Itinerary, Waves
from agent.seams import Formation, Perception
from agent.wire import NeighborRecordMsg, StatusMsg, key_alive, key_status, reason

log = logging.getLogger("agent.phases.runner")


class Fresh(NoJournal):
    """No crash recovery: every start is a fresh search, and no journal is kept."""

    def start(self) -> tuple[Phase, NeighborRecordMsg | None]:
        return Phase.SEARCH, None

    def finish(self, end: str) -> None:
        """Nothing is kept."""


class Runner:
    """Drives one robot through the phases; :meth:`run` returns the exit code.

    It depends only on the seams of :mod:`agent.seams`: a :class:`~agent.body.base.Body`
    (zenoh world, NAOqi or in-process world), a :class:`~agent.seams.Perception` and a
    :class:`~agent.seams.Formation`; the bus carries the exchange between agents.
    ``recovery`` builds its crash recovery from its crew (None: none, :class:`Fresh`).
    """

    def __init__(
        self,
        bus: Bus,
        body: Body,
        config: AgentConfig,
        perception: Perception,
        formation: Formation,
        clock: Callable[[], float] = time.monotonic,
        recovery: Callable[[Crew], Recovery] | None = None,
    ) -> None:
        if body.robot_id != config.robot_id:
            raise ValueError(f"robot {body.robot_id} driven with config for {config.robot_id}")
        if config.publish_camera:  # every analysed frame offered to viewers
            perception = CameraFeed(perception, bus, config.robot_id, lambda: body.t_sim, clock)
        self.ctx = ctx = Context.of(bus, body, config, perception, formation, clock)
        self.course = course = Itinerary()
        self.membership = fleet = Membership(ctx)
        self.motion = Motion(ctx, fleet)
        self.safe_steps = SafeSteps(ctx, fleet, self.motion, course)
        self.search = Search(ctx, self.motion)
        self.agreeing = Agreeing(ctx, fleet)
        self.research = Research(ctx, fleet, self.motion, self.search)
        self.waves = Waves(ctx, fleet, self.motion, self.safe_steps, course)
        self.hold = Hold(ctx, fleet, self.motion, self.safe_steps, course)
        self.reshaping = Reshaping(ctx, fleet, fleet.commands, course, self.walk_reshape)
        self.circle = CirclePattern(ctx, fleet, course)
        crew = Crew(ctx, fleet, self.motion, self.waves, course, self.search)
        self.recovery: Recovery = Fresh() if recovery is None else recovery(crew)
        ctx.report.journal = self.recovery

    def run(self) -> int:
        """Join, resume or start afresh, walk the phases; 0 once ``done``, 1 on a safe stop."""
        try:
            self.membership.start()
            stage, record = self.recovery.start()
            self.phases(stage, record)
            self.recovery.finish("done")
            return 0
        except KeyboardInterrupt:  # stopped by the operator: the run is over for this robot
            self.recovery.finish("stopped")
            raise
        except (AgentFailure, MarchHalt, BodyError, ValueError) as exc:
            return self.fail(reason(exc))
        except Exception as exc:  # a bug or an input nobody foresaw: stop safely, never crash
            log.error(
                "robot %d: unexpected %s\n%s",
                self.ctx.me,
                reason(exc),
                "".join(traceback.format_tb(exc.__traceback__))[-2000:],
            )
            try:
                return self.fail(f"unexpected {reason(exc)}")
            except Exception as exc2:
                log.error("robot %d could not publish failed: %s", self.ctx.me, reason(exc2))
                return 1
        finally:
            with contextlib.suppress(BodyError):
                self.ctx.body.stop()

    def phases(self, stage: Phase, record: NeighborRecordMsg | None) -> None:
        """The phases in order, entered at ``stage`` (``search`` afresh, or where the
        journal says: ``agree``, ``wait``, ``move``, ``hold``)."""
        if stage == Phase.SEARCH:
            self.ctx.report.status(Phase.START, 0.0, "joined", force=True)
            record = self.search.localise(self.search.sweep())  # SEARCH, LOCALISE
        if stage in (Phase.SEARCH, Phase.AGREE):
            assert record is not None
            self.waves.make_plan(self.agree(record))  # EXCHANGE/AGREE (→ re-search), PLAN
        if stage in (Phase.SEARCH, Phase.AGREE, Phase.WAIT):
            self.waves.wait_for_earlier_waves()  # WAIT
        if stage in (Phase.SEARCH, Phase.AGREE, Phase.WAIT, Phase.MOVE):
            self.waves.move()  # MOVE
        if self.ctx.cfg.orientation == "cp" and len(self.course.plan.robots) > 1:
            # the circle pattern's circle: fine-tune on the centre (or not), DONE; then
            # the formation from it (PLAN, WAIT, MOVE, HOLD, (MARCH), DONE)
            self.hold.run(march=False, tune=self.ctx.cfg.cp_tune)
            self.circle.plan()
            self.waves.wait_for_earlier_waves()
            self.waves.move()
            self.hold = Hold(self.ctx, self.membership, self.motion, self.safe_steps, self.course)
        self.hold.run()  # HOLD, CORRECT, (MARCH), DONE
        self.reshaping.run()  # (RESHAPE: PLAN, WAIT, MOVE, HOLD, DONE), as commanded

    def walk_reshape(self) -> None:
        """A reshape's plan walked as every plan: WAIT, MOVE, HOLD (a new hold: its
        parent, its checks), DONE; no march."""
        self.waves.wait_for_earlier_waves()
        self.waves.move()
        Hold(self.ctx, self.membership, self.motion, self.safe_steps, self.course).run(False)

    def agree(self, record: NeighborRecordMsg) -> Decision[NeighborRecordMsg]:
        """Agreement rounds, with re-search rounds (4.1.3 rule 2) until the agreed records
        leave nobody outside the fleet; AgentFailure when the fleet does not agree."""
        while True:
            decision = self.agreeing.agree(record)
            if decision.kind != "agreed":
                raise AgentFailure(decision.reason)
            again = self.research.next_round(decision)
            if again is None:
                return decision
            record = again

    def fail(self, reason: str) -> int:
        """Stop safely: publish ``failed`` with ``reason``, let it reach the others; 1."""
        log.error("robot %d failed: %s", self.ctx.me, reason)
        self.ctx.report.status(Phase.FAILED, 0.0, error=reason, force=True)
        self.recovery.finish("failed")
        # let the failure status and any pending digest reach the others
        end = self.ctx.clock() + 1.0
        while self.ctx.clock() < end:
            self.membership.wait_until(end)  # or news
        return 1


def report_unavailable(bus: Bus, robot_id: int, reason: str) -> int:
    """An agent that cannot run (perception or formation core missing) joins, publishes
    ``failed`` with ``reason`` so the fleet stops safely, and returns exit code 1."""
    log.error("robot %d cannot run: %s", robot_id, reason)
    bus.declare_alive(key_alive(robot_id))
    msg = StatusMsg(sender=robot_id, phase=Phase.FAILED.value, error=reason[:500])
    bus.publish(key_status(robot_id), msg, "status")
    bus.drain(1.0)
    return 1
