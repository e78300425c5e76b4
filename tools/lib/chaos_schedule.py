"""The fault schedule of one chaos run (``tools.eval_chaos``; docs/design.md §6 fault injection,
a random mix of faults per run): which faults strike when, drawn from a numpy ``Generator`` seeded
by the run's seed, so that a run can be repeated fault for fault.

The papers assume robots, radios and the robot's own body never fail. A schedule mixes,
over the first ``horizon_s`` seconds after the agents started:

* **agent kills** (``kill-agent``): SIGKILL of one agent, or of two at once, each started
  again (same id, same ``--state-dir``) after its own random 1–5 s; an episode may kill
  the same agent again shortly after its restart (the same agent twice in a row). A
  robot is never killed while it is down.
* **router restarts** (``kill-router``): the router killed and started again on the same
  endpoint after a random 1–5 s.
* **loss bursts** (``loss``): every agent host drops each packet with a probability from
  0 to ``max_loss`` per direction for 5–20 s (``tools.packet_drop``, the world's port
  exempt, as ``tools.eval_loss``); bursts do not overlap.
* **a slow world** (``reply_delay_s``): for the whole run, every camera and motion reply
  held for a random delay up to the drawn maximum (``python -m sim --reply-delay``).

The draws, in this fixed order: slow world or not and its maximum; the number of kill
episodes (0–2), router restarts (0–1) and loss bursts (0–2) (at least one timed fault:
none drawn gives one kill episode); each kill episode (single, twice, two at once),
each router restart, each burst. Times are rounded to 0.1 s, probabilities to 0.01.
:meth:`Schedule.tags` names what a schedule holds: ``kill``, ``kill-two``, ``kill-twice``,
``router``, ``loss``, ``slow``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from itertools import pairwise
from typing import Any

import numpy as np

KINDS = ("kill-agent", "kill-router", "loss")
TAGS = ("kill", "kill-two", "kill-twice", "router", "loss", "slow")
#: Kill episodes: one agent, the same agent twice in a row, two agents at once.
EPISODES = ("single", "twice", "two")
EPISODE_P = (0.4, 0.3, 0.3)
#: Earliest fault time (s after the agents started).
T_MIN = 2.0
#: A robot's down intervals keep this far apart (s).
MARGIN_S = 1.0


@dataclass(frozen=True)
class Limits:
    """The ranges faults are drawn from."""

    restart_s: tuple[float, float] = (1.0, 5.0)  # an agent's or the router's time down
    max_loss: float = 0.5  # loss per direction, drawn from [0, max_loss]
    burst_s: tuple[float, float] = (5.0, 20.0)  # a loss burst's length
    max_reply_delay_s: float = 2.0  # a slow world's maximum, drawn from [0.2, this]
    slow_p: float = 0.5  # probability that the world is slow
    twice_gap_s: tuple[float, float] = (1.0, 10.0)  # restart -> second kill


@dataclass(frozen=True)
class Fault:
    """One fault: at ``t`` seconds after the agents started."""

    t: float
    kind: str  # one of KINDS
    robots: tuple[int, ...] = ()  # kill-agent: the victims, 1..robots (two: at once)
    down_s: tuple[float, ...] = ()  # kill-agent: each victim's time down; kill-router: one
    loss: float = 0.0  # loss: drop probability per direction on every agent host
    duration_s: float = 0.0  # loss: the burst's length

    def end(self) -> float:
        """When the fault is over (the last restart, or the burst's end)."""
        return self.t + (self.duration_s if self.kind == "loss" else max(self.down_s, default=0))

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["robots"], d["down_s"] = list(self.robots), list(self.down_s)
        return d

    @staticmethod
    def from_dict(d: dict[str, Any]) -> Fault:
        return Fault(
            t=float(d["t"]),
            kind=str(d["kind"]),
            robots=tuple(int(r) for r in d.get("robots", ())),
            down_s=tuple(float(s) for s in d.get("down_s", ())),
            loss=float(d.get("loss", 0.0)),
            duration_s=float(d.get("duration_s", 0.0)),
        )


@dataclass(frozen=True)
class Action:
    """One step of a schedule's timeline: ``what`` at ``t`` for fault ``fault``."""

    t: float
    what: str  # kill, restart, kill-router, restart-router, loss-on, loss-off
    fault: int  # index into Schedule.faults
    robot: int = 0  # kill/restart: the robot (1..robots)
    loss: float = 0.0  # loss-on: the probability


@dataclass(frozen=True)
class Schedule:
    seed: int
    robots: int
    horizon_s: float
    reply_delay_s: float  # a slow world's maximum reply delay; 0: the world answers at once
    faults: tuple[Fault, ...] = field(default_factory=tuple)  # by time

    def tags(self, injected: set[int] | None = None) -> list[str]:
        """What the schedule holds, in the order of :data:`TAGS`; ``injected``: only these
        faults (indices) count (the slow world always does)."""
        fs = [f for i, f in enumerate(self.faults) if injected is None or i in injected]
        kills = [f for f in fs if f.kind == "kill-agent"]
        have = {
            "kill": any(len(f.robots) == 1 for f in kills),
            "kill-two": any(len(f.robots) >= 2 for f in kills),
            "kill-twice": any(set(a.robots) & set(b.robots) for a, b in pairwise(kills)),
            "router": any(f.kind == "kill-router" for f in fs),
            "loss": any(f.kind == "loss" for f in fs),
            "slow": self.reply_delay_s > 0,
        }
        return [t for t in TAGS if have[t]]

    def mix(self, injected: set[int] | None = None) -> str:
        """The tags as one label (``kill-two+loss+slow``; ``none``)."""
        return "+".join(self.tags(injected)) or "none"

    def actions(self) -> list[Action]:
        """The timeline: every kill with its restart, every burst with its end, by time
        (ties in the order the faults were listed)."""
        out: list[Action] = []
        for i, f in enumerate(self.faults):
            if f.kind == "kill-agent":
                for r, d in zip(f.robots, f.down_s, strict=True):
                    out.append(Action(f.t, "kill", i, robot=r))
                    out.append(Action(round(f.t + d, 1), "restart", i, robot=r))
            elif f.kind == "kill-router":
                out.append(Action(f.t, "kill-router", i))
                out.append(Action(round(f.t + f.down_s[0], 1), "restart-router", i))
            else:
                out.append(Action(f.t, "loss-on", i, loss=f.loss))
                out.append(Action(round(f.t + f.duration_s, 1), "loss-off", i))
        order = {"restart": 0, "restart-router": 0, "loss-off": 0}  # ends before starts
        return sorted(out, key=lambda a: (a.t, order.get(a.what, 1), a.fault, a.robot))

    def to_dict(self) -> dict[str, Any]:
        return {
            "seed": self.seed,
            "robots": self.robots,
            "horizon_s": self.horizon_s,
            "reply_delay_s": self.reply_delay_s,
            "tags": self.tags(),
            "faults": [f.to_dict() for f in self.faults],
        }

    @staticmethod
    def from_dict(d: dict[str, Any]) -> Schedule:
        return Schedule(
            seed=int(d["seed"]),
            robots=int(d["robots"]),
            horizon_s=float(d["horizon_s"]),
            reply_delay_s=float(d["reply_delay_s"]),
            faults=tuple(Fault.from_dict(f) for f in d["faults"]),
        )


# =========================================================================== drawing


class _Down:
    """Each robot's down intervals so far (a robot is not killed while it is down)."""

    def __init__(self) -> None:
        self.spans: dict[int, list[tuple[float, float]]] = {}

    def free(self, robot: int, t0: float, t1: float) -> bool:
        return all(t1 + MARGIN_S <= a or t0 >= b + MARGIN_S for a, b in self.spans.get(robot, []))

    def take(self, robot: int, t0: float, t1: float) -> None:
        self.spans.setdefault(robot, []).append((t0, t1))


def _r(x: float, digits: int = 1) -> float:
    return round(float(x), digits)


def draw(seed: int, robots: int, horizon_s: float = 40.0, limits: Limits = Limits()) -> Schedule:
    """The schedule of the run with ``seed`` (see the module docstring)."""
    if robots < 1:
        raise ValueError(f"robots {robots} must be >= 1")
    if not horizon_s > T_MIN:
        raise ValueError(f"horizon {horizon_s} s must be > {T_MIN:g} s")
    rng = np.random.default_rng(seed)
    lim = limits
    slow = bool(rng.random() < lim.slow_p)
    delay = _r(rng.uniform(min(0.2, lim.max_reply_delay_s), lim.max_reply_delay_s), 2)
    n_kill, n_router, n_loss = (int(rng.integers(0, k + 1)) for k in (2, 1, 2))
    if n_kill + n_router + n_loss == 0:
        n_kill = 1
    faults: list[Fault] = []
    down = _Down()

    def when() -> float:
        return _r(rng.uniform(T_MIN, horizon_s))

    def pause() -> float:
        return _r(rng.uniform(*lim.restart_s))

    for _ in range(n_kill):
        kind = str(rng.choice(EPISODES, p=EPISODE_P))
        if kind == "two" and robots < 2:
            kind = "single"
        t, d = when(), pause()
        if kind == "two":
            pair = sorted(int(v) + 1 for v in rng.choice(robots, size=2, replace=False))
            d2 = pause()
            if all(down.free(r, t, t + dd) for r, dd in zip(pair, (d, d2), strict=True)):
                for r, dd in zip(pair, (d, d2), strict=True):
                    down.take(r, t, t + dd)
                faults.append(Fault(t, "kill-agent", tuple(pair), (d, d2)))
            continue
        victim = int(rng.integers(1, robots + 1))
        if kind == "single":
            if down.free(victim, t, t + d):
                down.take(victim, t, t + d)
                faults.append(Fault(t, "kill-agent", (victim,), (d,)))
            continue
        t2 = _r(t + d + rng.uniform(*lim.twice_gap_s))
        d2 = pause()
        if down.free(victim, t, t + d) and down.free(victim, t2, t2 + d2):
            down.take(victim, t, t + d)
            down.take(victim, t2, t2 + d2)
            faults += [
                Fault(t, "kill-agent", (victim,), (d,)),
                Fault(t2, "kill-agent", (victim,), (d2,)),
            ]
    for _ in range(n_router):
        faults.append(Fault(when(), "kill-router", down_s=(pause(),)))
    bursts: list[Fault] = []
    for _ in range(n_loss):
        t = _r(rng.uniform(0.0, horizon_s))
        length = _r(rng.uniform(*lim.burst_s))
        p = _r(rng.uniform(0.0, lim.max_loss), 2)
        if all(t + length + MARGIN_S <= b.t or t >= b.end() + MARGIN_S for b in bursts):
            bursts.append(Fault(t, "loss", loss=p, duration_s=length))
    faults += bursts
    faults.sort(key=lambda f: (f.t, KINDS.index(f.kind), f.robots))
    return Schedule(seed, robots, float(horizon_s), delay if slow else 0.0, tuple(faults))


def with_injected(faults: list[dict[str, Any]]) -> set[int]:
    """Indices of the faults (rows of a run's JSON) that were injected."""
    return {i for i, f in enumerate(faults) if f.get("injected_at_s") is not None}
