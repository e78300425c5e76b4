"""Which robot's record does not fit, or nobody (docs/design.md §9; the check the papers
leave out: NAO paper 4.1.2 trusts every record).

One hypothesis test per robot on the measured sighting noise, at one false-alarm rate
(:mod:`~agent.core.formation.frame.faults.fault_test`: rejected pairs and lost strays,
the others' masks by :mod:`~agent.core.formation.frame.faults.heading_test`, a bias of
its own sightings by :mod:`~agent.core.formation.frame.faults.bias_test`); NAOs without
a record that the fleet sees (:mod:`~agent.core.formation.frame.faults.outsiders`); a
robot tested alone against the others framed without its record
(:mod:`~agent.core.formation.frame.faults.alone`). The frame room's
:func:`~agent.core.formation.frame.fleet_frame.fleet_frame` runs them on its candidate
frames.
"""
