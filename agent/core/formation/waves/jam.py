"""No robot jams for good: who blocks a robot, who yields, and when the fleet stops
(dense fleets; an addition to NAO paper 4.2 and 5.2.2 (iii) steps 5–7, where the robots
walk their planned paths open loop and never meet).

The plan keeps every path 2·radius from every robot it may meet (:mod:`safety`,
:mod:`execution`); the safe-step check before each step keeps ``2·radius + margin``
(agent/core/control/corridor.py). In a dense fleet a path may end between those two
distances from a robot that has not moved yet: the walking robot cannot take its last
steps (the corridor rule does not walk round a NAO on its goal), and that robot waits for
it to hold (the plan's ``after`` list). Neither moves: a jam. The rules here settle it,
from what every agent knows alike, the agreed plan and the statuses each robot publishes:

1. **Who blocks.** The blocked robot names its blocker (:func:`blocker_of`): the member
   whose expected place (:func:`expected_places`: its start while it has not moved, its
   slot once it holds, none while it walks) is nearest the NAO it sees on its way, within
   ``tolerance``; -1 if none (a NAO not in the plan, or one walking). A robot *has not
   moved* (:func:`at_start`) while its phase is one before walking (:data:`UNMOVED`), and
   also in its move phase for as long as its status says it has walked nothing of its
   path (``walked`` 0): it is turning towards its path, or waiting for its own way to
   clear. In its move phase with some of its path walked it is expected at that point of
   its path: it publishes its progress at once when it holds at a gate (:mod:`gates`),
   where it may stand a while. (In a dense fleet the NAO on a robot's way is often such a
   member, itself waiting and walking on a moment later: taken for "a NAO not in the
   plan", it would stop the robot after ``max_polls``.) It publishes the
   name in its status (``blocked_by``) once its rank-based patience is spent: that claim
   is what every agent then knows.
2. **Who yields.** A robot that has not moved yet and is named by such a claim starts at
   once if everything it still waits for is the claimant or waits (transitively, through
   the plan's ``after`` lists) for a claimant blocked by it (:func:`yields`): the two
   would otherwise wait for each other forever. Its own path was planned with the
   claimant holding; the safe steps check every step anyway.
3. **How long the blocked robot waits** (:func:`jam_verdict`): for a member named that has
   not moved yet or is in its move phase, up to ``long_polls`` (it yields, or moves in its
   turn, or walks on once those it waits for have passed; one that cannot fails, and rule
   4 stops everyone); for any other (one holding its slot, a NAO not named),
   ``max_polls``; then it stops with a reason that names the blocker.
4. **The fleet stops with one reason** (:func:`stop_reason`): once a member of the plan
   has failed, every agent stops, naming the failure that started it, so that no agent
   reports a finished formation around a hole. A failure that is itself such a stop
   names its root in its text and is copied from :data:`FLEET_STOP` on (what the agent
   put before it, the exception's name, is dropped); among several roots the lowest id
   is named (the same on every agent that heard them all).

Pure: ids, phases (the wire's phase names, as strings) and positions in, decisions out.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from agent.core.formation.waves.release import tail

#: phases of a robot that stands where it started (it has not walked yet)
UNMOVED = ("start", "search", "exchange", "agree", "plan", "wait")
#: phases of a robot that has walked its path and stands on its slot
HOLDING = ("hold", "march", "done")
#: the phase of a robot walking its path (it stands at its start until it has walked)
MOVING = "move"
#: the prefix of a stop caused by another member's failure (rule 4)
FLEET_STOP = "formation incomplete: "
WAIT, STOP = "wait", "stop"


def at_start(phase: str, walked: float = 0.0) -> bool:
    """Whether a robot whose last status gave ``phase`` and ``walked`` (m along its
    path) has not moved yet (rule 1): a phase before walking (:data:`UNMOVED`), nothing
    heard yet (``""``), or its move phase with nothing walked."""
    return phase in UNMOVED or phase == "" or (phase == MOVING and not walked > 0.0)


def expected_places(
    starts: Mapping[int, np.ndarray],
    targets: Mapping[int, np.ndarray],
    phases: Mapping[int, str],
    walked: Mapping[int, float] | None = None,
    paths: Mapping[int, np.ndarray] | None = None,
) -> dict[int, np.ndarray]:
    """Where each robot of the plan is expected to stand (rule 1): its start while it has
    not moved (:func:`at_start`, ``walked``: how far each robot's last status says it has
    walked along its path, 0 when not given), the point of its path (``paths``) at that
    arc length while it is in its move phase beyond its start, its target while in
    :data:`HOLDING`; robots failed, of an unknown phase, or walking without a path given
    are left out. Ids ascending; ``ValueError`` when the starts and targets name
    different robots."""
    if set(starts) != set(targets):
        raise ValueError("starts and targets must name the same robots")
    walked = {} if walked is None else walked
    paths = {} if paths is None else paths
    out: dict[int, np.ndarray] = {}
    for rid in sorted(starts):
        phase = phases.get(rid, "")
        w = walked.get(rid, 0.0)
        if at_start(phase, w):
            out[rid] = _point(starts[rid], f"start of {rid}")
        elif phase == MOVING and rid in paths and math.isfinite(w):
            out[rid] = _point(tail(paths[rid], w)[0], f"path of {rid} at {w}")
        elif phase in HOLDING:
            out[rid] = _point(targets[rid], f"target of {rid}")
    return out


def _point(p: np.ndarray, what: str) -> np.ndarray:
    a = np.asarray(p, dtype=np.float64).reshape(-1)
    if a.shape != (2,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{what} must be a finite (2,) point, got {p!r}")
    return a


def blocker_of(seen: np.ndarray, places: Mapping[int, np.ndarray], tolerance: float) -> int:
    """The robot whose expected place is nearest the NAO ``seen`` (same frame), within
    ``tolerance`` m; -1 if none. Ties go to the lower id."""
    if not (math.isfinite(tolerance) and tolerance >= 0.0):
        raise ValueError(f"tolerance must be finite and >= 0, got {tolerance!r}")
    p = _point(seen, "the NAO seen")
    best, best_d = -1, math.inf
    for rid in sorted(places):
        d = float(np.hypot(*(_point(places[rid], f"place of {rid}") - p)))
        if d <= tolerance and d < best_d:
            best, best_d = rid, d
    return best


def waits_for(after: Mapping[int, Sequence[int]], me: int, other: int) -> bool:
    """Whether robot ``me`` waits for ``other``, directly or through others (``after``:
    robot id → the ids it waits for)."""
    seen: set[int] = set()
    stack = [me]
    while stack:
        for j in after.get(stack.pop(), ()):
            j = int(j)
            if j == other:
                return True
            if j not in seen:
                seen.add(j)
                stack.append(j)
    return False


def yields(
    after: Mapping[int, Sequence[int]],
    me: int,
    pending: Sequence[int],
    blocked_by: Mapping[int, int],
) -> list[int]:
    """The claimants robot ``me`` yields to (rule 2), ascending; empty: keep waiting.

    ``pending``: the robots ``me`` still waits for (not holding yet); ``blocked_by``:
    each member's published claim (-1: none). ``me`` yields when some robot claims to be
    blocked by it and every pending robot is such a claimant or waits for one."""
    claimants = sorted(int(i) for i, b in blocked_by.items() if int(b) == me and int(i) != me)
    if not claimants or not pending:
        return []
    for p in pending:
        if int(p) in claimants:
            continue
        if not any(waits_for(after, int(p), c) for c in claimants):
            return []
    return claimants


@dataclass(frozen=True)
class JamVerdict:
    """What the blocked robot does next: ``action`` WAIT or STOP (then ``reason``)."""

    action: str
    reason: str = ""


def jam_verdict(
    me: int,
    blocker: int,
    blocker_phase: str,
    polls: int,
    max_polls: int,
    long_polls: int,
) -> JamVerdict:
    """Rule 3: robot ``me``, blocked for ``polls`` polls by ``blocker`` (-1: a NAO not
    named) whose last phase is ``blocker_phase``, waits or stops. ``long_polls`` bounds
    the wait for a blocker that has not moved yet or is in its move phase, ``max_polls``
    every other."""
    if polls < 0 or max_polls < 0 or long_polls < max_polls:
        raise ValueError(
            f"need polls >= 0 and 0 <= max_polls <= long_polls, got {polls}, {max_polls}, "
            f"{long_polls}"
        )
    will_move = blocker >= 0 and (blocker_phase in (*UNMOVED, "", MOVING))
    limit = long_polls if will_move else max_polls
    if polls < limit:
        return JamVerdict(WAIT)
    if blocker < 0:
        who = "a NAO not in the plan (or one walking)"
    else:
        who = f"robot {blocker} ({blocker_phase or 'not heard'})"
    return JamVerdict(STOP, f"robot {me} cannot reach its slot: {who} in its way for {polls} polls")


def stop_reason(failures: Mapping[int, str]) -> str:
    """Rule 4: the reason every agent stops with, once the members ``failures`` (id →
    published error) have failed; "" for none. A root failure (one that is not itself a
    fleet stop: no :data:`FLEET_STOP` in it) is named as ``formation incomplete: robot I
    failed: ERROR`` (the lowest id among the roots); with only fleet stops heard, the
    lowest id's text is copied from :data:`FLEET_STOP` on."""
    if not failures:
        return ""
    roots = sorted(i for i, e in failures.items() if FLEET_STOP not in e)
    if roots:
        i = roots[0]
        return f"{FLEET_STOP}robot {i} failed: {failures[i] or 'no reason given'}"
    text = failures[min(failures)]
    return text[text.index(FLEET_STOP) :]
