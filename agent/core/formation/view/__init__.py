"""One robot's view of a finished plan, read by the phases after planning: the plan in
the robot's own fixed frame (NAO paper 4.1.1 without its parallel frames, docs/design.md
§9; :mod:`~agent.core.formation.view.own_frame`), who may still pass its final alignment
(NAO paper 5.2.2; :mod:`~agent.core.formation.view.passers_by`) and the march route of
the whole pyramid (AUV paper I–II, docs/design.md §1 step 7;
:mod:`~agent.core.formation.view.route`).

Entry points: :func:`~agent.core.formation.view.own_frame.in_own_frame` (the waves
phase), :func:`~agent.core.formation.view.passers_by.passers_by` (hold),
:class:`~agent.core.formation.view.route.Route`, ``route_vector`` and ``station_offset``
(config, march, the harness). The top room: it reads the
:class:`~agent.core.formation.plan.Plan`, so nothing of the planner imports it.
"""
