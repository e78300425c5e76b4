"""The formation adapter (agent/adapters.py) keeps its last plan: the agreement's
adoption check and the planning phase plan the same records once (a plan cost ~7 CPU s an agent at
50 NAOs)."""

from __future__ import annotations

import pytest

from agent.adapters import FormationAdapter
from agent.core.formation.params import PlanParams
from agent.wire import NeighborRecordMsg
from tests.phases.fakes import records


def test_formation_adapter_keeps_its_last_plan(monkeypatch: pytest.MonkeyPatch) -> None:
    import agent.adapters as adapters

    calls: list[int] = []
    real = adapters.plan_from_records

    def counted(*args, **kwargs):  # type: ignore[no-untyped-def]
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(adapters, "plan_from_records", counted)
    fa = FormationAdapter()
    first = fa.plan(records(), PlanParams())
    assert fa.plan(records(), PlanParams()) is first and len(calls) == 1  # equal inputs
    assert fa.plan(records(), PlanParams(d_e=0.9)) is not first and len(calls) == 2
    # two robots that saw nobody: not connected, and the same error again, unplanned
    lone = tuple(NeighborRecordMsg(sender=i, round=0, neighbours=()) for i in (1, 2))
    for _ in range(2):
        with pytest.raises(ValueError):
            fa.plan(lone, PlanParams())
    assert len(calls) == 3
