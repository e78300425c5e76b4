"""The operator's side of reshaping (docs/formation.md "Reshaping"): command a fleet that
holds a shape to take the next, one shape after another, and time each transition.

:class:`Reshaper` is driven by what the fleet's statuses say (:class:`Seen`, per robot:
its phase, plan digest, sim time and detail): once every robot is ``done`` on one plan
D, it publishes the signed command (:func:`command_of`: base D and the shape), again
every ``resend`` s while a robot still shows D ``done`` and no refusal (a command lost
on the way is sent again; an agent acts on one number once); the transition is over
when every robot is ``done`` on one plan other than D (``held``), when every robot
refused it (``refused``: the reason is in their statuses), when one failed
(``failed``), or after ``timeout`` s. The sim time of a transition runs from the newest
status of the held fleet when the command went out to the newest ``done`` status on the
new plan; its wall time on the operator's clock.

``python -m tools.fleet reshape`` runs it over its own bus; ``tools.demo --reshape`` over
the run's observer (tools/harness/fleet.py).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

from agent.core.formation.shape.spec import TREE, Shape
from agent.wire import ReshapeMsg

#: Seconds between two sends of a command not yet taken by every robot.
RESEND_S = 2.0
#: What the status of a robot the fleet's check left out says (agent/phases/waves.py).
LEFT_OUT = "left out of the plan"


@dataclass(frozen=True)
class Seen:
    """A robot's last status as the operator heard it."""

    phase: str
    digest: str
    t_sim: float = 0.0
    detail: str = ""
    error: str = ""

    @property
    def left_out(self) -> bool:
        """The fleet's check left this robot out of the plan: it stands still, stopped
        by design, and is no member of the formation to reshape."""
        return self.phase == "failed" and LEFT_OUT in self.error


def command_of(shape: Shape, base: str, number: int) -> ReshapeMsg:
    """The command to take ``shape`` from the plan ``base``, numbered ``number``."""
    slots = tuple((int(p), float(d), float(a)) for p, d, a in shape.edges)
    return ReshapeMsg(
        command=number,
        base=base,
        name=shape.name[:64],
        rule=shape.rule,
        orient=shape.orient,
        shape_digest=shape.digest,
        slots=slots if shape.rule == TREE else (),
    )


def held_digest(seen: Mapping[int, Seen], robots: Collection[int]) -> str:
    """The plan every robot of ``robots`` is ``done`` on ("" if they are not all)."""
    digests = {seen[i].digest for i in robots if i in seen and seen[i].phase == "done"}
    if len(digests) != 1 or any(i not in seen or seen[i].phase != "done" for i in robots):
        return ""
    return next(iter(digests))


@dataclass
class Transition:
    """One commanded reshape and how it went."""

    shape: str
    command: int
    base: str
    plan: str = ""
    outcome: str = "pending"  # held | refused | failed | timeout
    detail: str = ""
    wall_s: float = math.nan
    sim_s: float = math.nan
    sends: int = 0

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class Reshaper:
    """Takes ``shapes`` in turn on the fleet of ``robots`` (module docstring);
    ``publish`` sends a command (signed by the operator's bus)."""

    shapes: Sequence[Shape]
    robots: Collection[int]
    publish: Callable[[ReshapeMsg], object]
    resend: float = RESEND_S
    timeout: float = 900.0
    first_command: int = 1
    done: list[Transition] = field(default_factory=list)
    _current: Transition | None = None
    _t0: float = 0.0
    _sim0: float = 0.0
    _last_send: float = -math.inf
    _stopped: bool = False

    @property
    def pending(self) -> bool:
        """Whether shapes are left to take (and nothing went wrong)."""
        return not self._stopped and len(self.done) < len(self.shapes)

    @property
    def ok(self) -> bool:
        """Every shape taken and held."""
        return len(self.done) == len(self.shapes) and all(t.outcome == "held" for t in self.done)

    def step(self, now: float, seen: Mapping[int, Seen]) -> bool:
        """Act on what the statuses say at ``now`` (the operator's clock, s); whether
        shapes are still pending."""
        if not self.pending:
            return False
        members = [i for i in self.robots if not (i in seen and seen[i].left_out)]
        cur = self._current
        if cur is None:
            base = held_digest(seen, members)
            if not base:
                return True
            k = len(self.done)
            cur = self._current = Transition(self.shapes[k].name, self.first_command + k, base)
            self._t0, self._sim0 = now, max(seen[i].t_sim for i in members)
            self._send(now)
            return True
        self._judge(cur, now, {i: seen[i] for i in members})
        if cur.outcome != "pending":
            self.done.append(cur)
            self._current = None
            self._stopped = cur.outcome != "held"
            return self.step(now, seen)  # the next shape, at once
        still = [i for i in members if seen[i].phase == "done" and seen[i].digest == cur.base]
        if still and now - self._last_send >= self.resend:
            self._send(now)
        return True

    def _send(self, now: float) -> None:
        cur = self._current
        assert cur is not None
        self.publish(command_of(self.shapes[len(self.done)], cur.base, cur.command))
        cur.sends += 1
        self._last_send = now

    def _judge(self, cur: Transition, now: float, seen: Mapping[int, Seen]) -> None:
        """``seen``: the members' statuses (the robots left out apart)."""
        failed = {i: s.detail for i, s in seen.items() if s.phase == "failed"}
        refusal = f"reshape {cur.command} to "
        refused = [
            i
            for i, s in seen.items()
            if s.digest == cur.base and s.detail.startswith(refusal) and "refused" in s.detail
        ]
        new = held_digest(seen, list(seen))
        if failed:
            cur.outcome, cur.detail = "failed", f"robots {sorted(failed)} failed"
        elif new and new != cur.base:
            cur.outcome, cur.plan = "held", new
            cur.sim_s = max(s.t_sim for s in seen.values()) - self._sim0
            cur.detail = f"every robot done on plan {new[:12]}"
        elif refused and len(refused) == len(seen):
            cur.outcome, cur.detail = "refused", seen[refused[0]].detail
        elif now - self._t0 > self.timeout:
            cur.outcome, cur.detail = "timeout", f"not held within {self.timeout:g} s"
        else:
            return
        cur.wall_s = now - self._t0


def judge_reshapes(result: dict[str, Any], plan: Any, params: Any) -> Any:
    """The evaluator's side (tools/harness/judge.py): the plan the fleet holds after the
    transitions ``result["reshapes"]`` says were held, recomputed from ``plan`` (the
    evaluator's own of the signed records) with the agreed ``params``, into
    ``result["evaluator_plan_digest"]``; ``result["reshape_ok"]``: every commanded shape
    held. Returns the final plan."""
    from dataclasses import replace

    from agent.config import load_shape
    from agent.core.formation.reshape import transition_plan

    specs = result.get("reshape_specs", [])
    held = [t for t in result.get("reshapes", []) if t.get("outcome") == "held"]
    result["reshape_ok"] = len(held) == len(specs)
    for spec in specs[: len(held)]:
        shape = load_shape(spec)
        plan = transition_plan(plan, shape, replace(params, shape=shape))
    result["evaluator_plan_digest"] = str(plan.digest)
    return plan


def final_shape_spec(result: dict[str, Any]) -> str:
    """The shape the fleet should hold at the end: the last reshape held (the first
    shape without one)."""
    specs = result.get("reshape_specs", [])
    held = [t for t in result.get("reshapes", []) if t.get("outcome") == "held"]
    return str(specs[len(held) - 1]) if held else str(result.get("shape_spec", "pyramid"))
