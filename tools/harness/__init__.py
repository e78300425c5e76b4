"""One harness for every tool and test that runs the fleet as processes (one way to start, observe
and judge runs).

``fleet``: a run described (``FleetSpec``) and run on this machine (``Fleet``: started,
observed, stopped, judged); ``fleet_flags``: the command-line flags of a run (``tools.demo``'s).
``procs``: ports, the world, router, agents and rogues, the fleet's network, stopping.
``observe``: the MCAP recorder, the bus observer, the live status lines.
``view``: a run as people see it: Foxglove's schemas, the scene's channels of a recording,
the live server and the page in the browser (``view.foxglove``, ``view.scene``,
``view.live``, ``view.webpage``).
``render``: the render workers of a run (cameras drawn beside the world).
``judge``: a run judged from ground truth, its outcome (one rule), the result table, the
formation figure.
``truth``: the ground truth read as a user would: who moved, the pyramid's shape from the
true final poses.
``pairs``: the planned formation's child-parent pairs judged by the robots' own formula.
``monitor``: one run observed and judged by a process of its own (``tools.eval_loss``,
the compose observer).
``report``: the evaluation tools' shared runs JSON, table and outcome figure, and their
matrix of runs (``run_matrix``).
``progress``: the progress line of a long evaluation.
``hosts``: a run's fleet on test hosts (network namespaces) with the levers of fault
injection (``tools.eval_loss``, ``tools.eval_chaos``, ``tools.eval_render``).
"""
