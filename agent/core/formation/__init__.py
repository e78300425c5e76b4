"""The formation core: neighbour records -> one safe pyramid plan (NAO paper 4.1-4.2,
5.1-5.2; AUV paper II-III). Pure: numpy and scipy only.

The entry point is :mod:`agent.core.formation.plan` (``plan_from_records``,
``plan_from_positions``, the :class:`~agent.core.formation.plan.Plan`); its settings are
:mod:`agent.core.formation.params`. The rest lives in rooms, one concept each, lowest
first (a room imports only rooms below it; ``tests/test_layers.py`` checks the order):

1. :mod:`~agent.core.formation.frame` - the common frame from the neighbour records
   (4.1.2-4.1.3), and :mod:`~agent.core.formation.shape` - the pyramid pattern (AUV
   eqs. 5-8, NAO eqs. 12-13) and its pair check (5.1.1); the two never import each other;
2. :mod:`~agent.core.formation.paths` - who walks to which slot, along which straight or
   bent path (4.2, Lemma 1);
3. ``params`` - the planner's parameters (names the choices of the rooms below);
4. :mod:`~agent.core.formation.waves` - when each robot walks: the safety rule, waves,
   release points, detours, the choice of plan, and the rules that execute it in time;
5. ``plan`` - records -> plan;
6. :mod:`~agent.core.formation.view` - one robot's view of a finished plan (its own
   frame, the march route, who may still pass it), read by the phases.
"""
