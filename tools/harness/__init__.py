"""One harness for every tool and test that runs the fleet as processes (issue #9).

``procs``: ports, the world, router, agents and rogues, the fleet's network, stopping.
``observe``: the MCAP recorder, the bus observer, the live status lines.
``judge``: a run judged from ground truth, the result table, the formation figure.
``run``: one demo run (world, agents, observation, judgement), as ``tools.demo`` runs it.
"""
