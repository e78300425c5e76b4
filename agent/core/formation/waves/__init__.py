"""When each robot walks: the safety rule and the plan in time (NAO paper 4.2 and
5.2.2 (iii) step 7, "the leader goes to its destination firstly, and then the followers"; our
strengthening of Lemma 1; static obstacles, 5.1.2).

The rule (:mod:`~agent.core.formation.waves.safety`) and its release points
(:mod:`~agent.core.formation.waves.release`); the wave scheduler
(:mod:`~agent.core.formation.waves.scheduler` with ``via_points``), packing
(:mod:`~agent.core.formation.waves.packing`) and detours
(:mod:`~agent.core.formation.waves.detours`) that make one assignment a safe plan
(:mod:`~agent.core.formation.waves.scheduled`); the choice among candidate plans
(:mod:`~agent.core.formation.waves.choice`) and the plan around obstacles
(:mod:`~agent.core.formation.waves.obstacles`); how a plan executes and how long it takes
(:mod:`~agent.core.formation.waves.execution`), and who yields when robots block each
other at run time (:mod:`~agent.core.formation.waves.jam`).

Entry points: :func:`~agent.core.formation.waves.choice.choose`,
:func:`~agent.core.formation.waves.scheduled.scheduled_plan` and
:func:`~agent.core.formation.waves.obstacles.plan_near_obstacles` /
``plan_around_obstacles`` (used by :mod:`agent.core.formation.plan`);
``execution`` and ``safety.check_safety`` for the tools; ``jam`` and
``release.walked_along`` for the phases. Imports :mod:`~agent.core.formation.paths`,
:mod:`~agent.core.formation.shape` and ``params``, never ``plan``.
"""
