"""Long computations while the bus is pumped (so that agreement scales to 50 NAOs and more: an agent
keeps hearing the fleet while it plans).

An agent that agreed must go on answering the agreement while it plans: it repeats its
digest until every member has moved on (:mod:`agent.core.agreement`, NAO paper 4.1.2's
exchange made loss-tolerant). At 100 NAOs on 2 cores a plan took minutes; robot 77,
planning, repeated nothing meanwhile, and three members whose copy of its last digest
had been dropped stopped on "no news for 300 s". The plan is the same whatever thread
computes it: it reads only the agreed records and parameters.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from concurrent.futures import TimeoutError as Pending
from typing import TypeVar

from agent.core.formation.plan import Plan
from agent.phases.context import Context
from agent.phases.roles import Fleet
from agent.wire import NeighborRecordMsg

#: Seconds between two pumps of the bus while the plan is computed.
PLAN_PUMP_S = 0.1

T = TypeVar("T")


def while_pumping(compute: Callable[[], T], pump: Callable[[], None], every: float) -> T:
    """``compute()`` in a worker thread, ``pump()`` here every ``every`` seconds until it
    is done; its result, or its exception raised here (module docstring). A pump that
    raises waits for the computation (the worker is never left running) and raises."""
    if not every > 0:
        raise ValueError(f"every must be > 0 s, got {every}")
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="plan") as pool:
        job = pool.submit(compute)
        while True:
            try:
                return job.result(timeout=every)
            except Pending:
                if job.done():  # compute itself raised a TimeoutError
                    raise
                pump()


def plan_pumping(ctx: Context, fleet: Fleet, records: tuple[NeighborRecordMsg, ...]) -> Plan:
    """The formation core's plan of ``records`` with this agent's parameters, computed
    while ``fleet`` is pumped (:func:`while_pumping`); ``ValueError`` if it refuses."""
    params = ctx.cfg.plan_params()
    return while_pumping(
        lambda: ctx.formation.plan(records, params), lambda: fleet.pump(0.0), PLAN_PUMP_S
    )
