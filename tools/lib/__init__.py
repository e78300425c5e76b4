"""The evaluation tools' libraries (no commands here): what a tool draws, generates, fits or
reports besides starting and judging fleets (that is :mod:`tools.harness`).

``chaos_schedule``: the seeded fault schedules of ``tools.eval_chaos``; ``chaos_injector``:
a schedule walked on a fleet's levers; ``chaos_report``: its rows, table and figure.
``faults_report``, ``loss_report``, ``scale_report``, ``frames_report``,
``perception_report``: the rows, tables and figures of ``tools.eval_faults``,
``tools.eval_loss``, ``tools.eval_scale``, ``tools.eval_frames`` and
``tools.eval_perception``.
``frame_fit``: where the fleet's common frame lies in the world (a rigid fit), for the judge.
``fuzz_payloads``: the malformed messages of ``tools.fuzz`` and tests/wire/test_fuzz.py.
``obstacle_scenario``: obstacles on the fleet's straight paths (``tools.demo --obstacles``).
``perception_scenes``: the labelled views of ``tools.eval_perception``.
"""
