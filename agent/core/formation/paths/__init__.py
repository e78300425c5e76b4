"""Who walks where: the assignment of robots to slots and the paths they walk (NAO paper
4.2, Lemma 1, eq. 11; AUV paper III.C).

The segment geometry of the paths (:mod:`~agent.core.formation.paths.geometry`) and its
exact close-pair search (:mod:`~agent.core.formation.paths.close_pairs`), the
assignment strategies (:mod:`~agent.core.formation.paths.assignment`), bent paths for
the worst fleets (start sidesteps, :mod:`~agent.core.formation.paths.kinks`; bundle
lanes, :mod:`~agent.core.formation.paths.lanes`; a wide shape's row lanes and row shift,
:mod:`~agent.core.formation.paths.row_lanes`, :mod:`~agent.core.formation.paths.row_shift`),
and the banded plan that always exists
(:mod:`~agent.core.formation.paths.fallback`).

Entry points: :func:`~agent.core.formation.paths.assignment.assign` (used by the choice
of plan in :mod:`~agent.core.formation.waves`) and
:func:`~agent.core.formation.paths.fallback.banded_plan` (used by
:mod:`agent.core.formation.plan`). Imports only :mod:`~agent.core.formation.shape`.
"""
