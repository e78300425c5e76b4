"""The pattern: the planar pyramid, its slots and its frame (AUV paper II, III.B eqs.
5-8; NAO paper 4.2 eqs. 12-13, the PCA frame, or the CP frame), the other shapes as
trees of slots (each child at a distance and angle from its parent: the built-ins and
the formation file), and the pair check of a built formation (NAO paper 5.1.1).

Entry points: :class:`~agent.core.formation.shape.spec.Shape` (its slots for N robots
and its digest; :data:`~agent.core.formation.shape.spec.BUILTIN`,
:func:`~agent.core.formation.shape.schema.parse_shape`),
:func:`~agent.core.formation.shape.layout.shape_frame` and the placed slots of
:mod:`~agent.core.formation.shape.layout` (used by :mod:`agent.core.formation.plan` and
the path rooms); :func:`~agent.core.formation.shape.verdict.check_edge` (the robots' own
check after hold, and the harness's ground truth). The lowest room, beside
:mod:`~agent.core.formation.frame`: it imports no other room of the formation.
"""
