"""The chaos soak's injector (``tools.eval_chaos``; docs/faults.md "Chaos soak"): a fault
schedule (:mod:`tools.lib.chaos_schedule`) walked on a running fleet's levers.
"""

from __future__ import annotations

from typing import Any, Protocol

from tools.lib.chaos_schedule import Schedule


class Levers(Protocol):
    """What the injector pulls (:class:`tools.harness.hosts.HostFleet`; a fake in tests)."""

    def running(self, rid: int) -> bool: ...

    def all_exited(self) -> bool: ...

    def kill_agent(self, rid: int) -> None: ...

    def start_agent(self, rid: int, append: bool = False) -> None: ...

    def kill_router(self) -> None: ...

    def start_router(self) -> None: ...

    def set_loss(self, loss: float) -> None: ...

    def clear_loss(self) -> None: ...


class Injector:
    """Walks a schedule's time line (:meth:`Schedule.actions`) on a fleet's levers.

    Robots of the schedule (1..robots) are the world's ids in order. A kill of an agent
    that has exited is skipped (its restart too); the router and the loss are left alone
    once every agent has exited and no restart is pending (the run is over)."""

    def __init__(self, sched: Schedule, fleet: Levers, ids: list[int], say: Any = None) -> None:
        self.sched, self.fleet, self.ids = sched, fleet, ids
        self.todo = sched.actions()
        self.k = 0
        self.down: set[int] = set()  # robots killed whose restart is pending
        self.router_down = False
        self.loss_on = False
        self.injected_at: dict[int, float] = {}
        self.notes: dict[int, str] = {}
        self.events: list[dict[str, Any]] = []
        self._say = say

    def pending(self) -> bool:
        """A restart is still to come."""
        return bool(self.down) or self.router_down

    def over(self) -> bool:
        return self.fleet.all_exited() and not self.pending()

    def step(self, now: float) -> None:
        """Do every action due at ``now`` (seconds after the agents started)."""
        while self.k < len(self.todo) and self.todo[self.k].t <= now:
            a = self.todo[self.k]
            self.k += 1
            rid = self.ids[a.robot - 1] if a.robot else 0
            done = self._do(a.what, a.fault, rid, a.robot, a.loss)
            if done:
                self.events.append({"t": round(now, 1), "action": a.what, "fault": a.fault,
                                    "robot": rid, "loss": a.loss})  # fmt: skip
                if a.what in ("kill", "kill-router", "loss-on"):
                    self.injected_at.setdefault(a.fault, round(now, 1))
                if self._say is not None:
                    extra = f" robot {rid}" if rid else f" {a.loss:.0%}" if a.loss else ""
                    self._say(f"[{now:6.1f}s] {a.what}{extra}")

    def _do(self, what: str, fault: int, rid: int, robot: int, loss: float) -> bool:
        f = self.fleet
        if what == "kill":
            if not f.running(rid):
                self.notes[fault] = f"robot {rid} had exited"
                return False
            f.kill_agent(rid)
            self.down.add(robot)
        elif what == "restart":
            if robot not in self.down:
                return False
            f.start_agent(rid, append=True)
            self.down.discard(robot)
        elif what in ("kill-router", "loss-on"):
            if self.over():
                self.notes[fault] = "the agents had finished"
                return False
            if what == "kill-router":
                f.kill_router()
                self.router_down = True
            else:
                f.set_loss(loss)
                self.loss_on = True
        elif what == "restart-router":
            if not self.router_down:
                return False
            f.start_router()
            self.router_down = False
        elif what == "loss-off":
            if not self.loss_on:
                return False
            f.clear_loss()
            self.loss_on = False
        return True

    def finish(self) -> None:
        """The run is over: the loss cleared, the faults never reached noted."""
        if self.loss_on:
            self.fleet.clear_loss()
            self.loss_on = False
        for i in range(len(self.sched.faults)):
            if i not in self.injected_at:
                self.notes.setdefault(i, "the agents had finished")

    def schedule_doc(self) -> dict[str, Any]:
        """The schedule with each fault's ``injected_at_s`` and ``note``."""
        doc = self.sched.to_dict()
        for i, f in enumerate(doc["faults"]):
            f["injected_at_s"] = self.injected_at.get(i)
            f["note"] = self.notes.get(i, "")
        doc["injected_tags"] = self.sched.tags(set(self.injected_at))
        return doc
