"""What the fleet does once it holds a shape: the transitions to another shape, each
planned by every agent alike and walked as every plan.

* :mod:`~agent.phases.transitions.reshaping`: on the operator's command
  (docs/formation.md "Reshaping"; the commands are :class:`agent.wire.ReshapeMsg`, signed
  by the ``operator`` identity alone);
* :mod:`~agent.phases.transitions.circle_pattern`: from the circle pattern's circle to
  the formation (AUV paper III.B.2.a, docs/formation.md "The circle pattern").
"""
