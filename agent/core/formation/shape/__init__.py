"""The pattern: the planar pyramid, its slots and its frame (AUV paper II, III.B eqs.
5-8; NAO paper 4.2 eqs. 12-13, the PCA frame, or the CP frame), and the pair check of a
built pyramid (NAO paper 5.1.1).

Entry points: :func:`~agent.core.formation.shape.pyramid.pyramid_frame` and the slots of
:mod:`~agent.core.formation.shape.pyramid` (used by :mod:`agent.core.formation.plan` and
the path rooms); :func:`~agent.core.formation.shape.verdict.check_pair` (the robots' own
check after hold, and the harness's ground truth). The lowest room, beside
:mod:`~agent.core.formation.frame`: it imports no other room of the formation.
"""
