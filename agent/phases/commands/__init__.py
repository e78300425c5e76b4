"""What the fleet does on its operator's command once it holds a shape (docs/formation.md
"Reshaping"): :mod:`~agent.phases.commands.reshaping`, the transition to another shape,
planned by every agent alike and walked as every plan. The commands themselves are
:class:`agent.wire.ReshapeMsg`, signed by the ``operator`` identity alone.
"""
