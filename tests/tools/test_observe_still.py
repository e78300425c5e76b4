"""tools/harness/observe.py ``observe_still``: after the agents' exits the observer waits for
a world that stands still (two truth samples alike), not a fixed time; a world still
walking a motion out is waited for up to the bound."""

from __future__ import annotations

import time
from collections.abc import Iterator

from agent.net.bus import Event
from agent.wire import TruthPosesMsg
from agent.wire.keys import KEY_WORLD_TRUTH_POSES
from tools.harness.observe import STILL, Observer, observe_still


class Samples:
    """A bus that brings one truth sample per drain: robot 1 at each x in turn."""

    def __init__(self, xs: Iterator[float]) -> None:
        self.xs, self.drains = xs, 0

    def drain(self, timeout: float) -> list[Event]:
        self.drains += 1
        time.sleep(min(timeout, 0.01))
        x = next(self.xs, None)
        if x is None:
            return []
        msg = TruthPosesMsg(t_sim=float(self.drains), poses=((1, x, 0.0, 0.5), (2, 1.0, 1.0, 0.0)))
        return [Event("msg", KEY_WORLD_TRUTH_POSES, msg)]


def test_a_world_standing_still_ends_the_wait_at_its_second_sample() -> None:
    obs, bus = Observer(t0=time.monotonic()), Samples(iter([2.0, 2.0 + STILL / 2, 5.0]))
    t = time.monotonic()
    observe_still(bus, obs, None, 5.0)  # type: ignore[arg-type]
    assert bus.drains == 2 and len(obs.truth) == 2 and time.monotonic() - t < 1.0


def test_samples_before_the_wait_do_not_count() -> None:
    obs, bus = Observer(t0=time.monotonic()), Samples(iter([2.0, 2.0]))
    obs.truth.extend([(0.0, {1: (2.0, 0.0, 0.5), 2: (1.0, 1.0, 0.0)})] * 2)
    observe_still(bus, obs, None, 5.0)  # type: ignore[arg-type]
    assert bus.drains == 2  # two new samples, though the last two held already


def test_a_robot_still_walking_is_waited_for_until_it_stops_or_the_bound() -> None:
    obs, bus = Observer(t0=time.monotonic()), Samples(iter([0.0, 0.1, 0.2, 0.3, 0.3]))
    observe_still(bus, obs, None, 5.0)  # type: ignore[arg-type]
    assert bus.drains == 5 and obs.truth[-1][1][1][0] == 0.3
    walking = Samples(iter(0.01 * k for k in range(10_000)))
    t = time.monotonic()
    observe_still(walking, Observer(t0=t), None, 0.3)  # type: ignore[arg-type]
    assert 0.3 <= time.monotonic() - t < 1.0 and walking.drains >= 3
