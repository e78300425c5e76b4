"""One harness for every tool and test that runs the fleet as processes (one way to start, observe
and judge runs).

``procs``: ports, the world, router, agents and rogues, the fleet's network, stopping.
``observe``: the MCAP recorder, the bus observer, the live status lines.
``scene``: the Foxglove channels of a recording (scene, plan, frames, log, statuses).
``foxglove``: Foxglove's well-known schemas as JSON Schema, and their message builders.
``judge``: a run judged from ground truth, its outcome (one rule), the result table, the
formation figure.
``truth``: the ground truth read as a user would: who moved, the pyramid's shape from the
true final poses.
``run``: one demo run (world, agents, observation, judgement), as ``tools.demo`` runs it.
``monitor``: one run observed and judged by a process of its own (``tools.eval_loss``,
the compose observer).
``report``: the evaluation tools' shared runs JSON, table and outcome figure.
``progress``: the progress line of a long evaluation.
``hosts``: one run's fleet on test hosts (network namespaces) with the levers of fault
injection (``tools.eval_chaos``).
"""
