"""The common frame from the neighbour records (NAO paper 4.1.1-4.1.3, Algorithm 2,
eqs. 9-10; AUV paper III.A eq. 4; docs/design.md §9 for starts that are not aligned).

What each robot shares (:mod:`~agent.core.formation.frame.records`), which sighting is
which robot (:mod:`~agent.core.formation.frame.neighbour_check`, eq. 9;
:mod:`~agent.core.formation.frame.pose_pairing`, ``pair_support``, ``firm_pairs``,
``reidentify`` without the papers' alignment), every start in one frame
(:mod:`~agent.core.formation.frame.common_frame`, eq. 10; the pose fit of
:mod:`~agent.core.formation.frame.poses` on ``robust_lm``), the consistency check that
names a robot whose sightings do not fit, or nobody (the sub-room
:mod:`~agent.core.formation.frame.faults`), and the re-search decision (:mod:`~agent.core.formation.frame.research`, 4.1.3
rule 2). The perceived obstacles are merged into the common frame beside this room
(:mod:`agent.core.formation.obstacle_map`, 5.1.2).

Entry points: :func:`~agent.core.formation.frame.fleet_frame.fleet_frame` (poses and the
robot left out, used by :mod:`agent.core.formation.plan`);
:func:`~agent.core.formation.frame.research.decide_research`,
:class:`~agent.core.formation.frame.records.NeighborRecord` (used by
``agent/adapters.py``). The lowest room: it imports no other room of the formation.
"""
