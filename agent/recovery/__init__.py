"""Crash recovery (docs/design.md §8 "Faults"; docs/faults.md "Crashed agents and restarted
routers"). The papers assume robots never crash; an agent started with ``--state-dir``
journals its state and, restarted after a crash, goes on where it was if its run is
still going.

What the journal holds and how it is kept durable
(:mod:`~agent.recovery.journal`), writing it at every phase change and before every
command (:mod:`~agent.recovery.journaling`), whether a journal's run is still going
(:mod:`~agent.recovery.runs`), and where a restarted agent goes on
(:mod:`~agent.recovery.resume`).

Entry point: :class:`~agent.recovery.crash_recovery.CrashRecovery`, the phase machine's
:class:`~agent.phases.roles.Recovery` (wired by ``agent/__main__.py``). The room builds on
the phases (their context, roles, reporter and record sets), never the reverse: the
phase machine knows crash recovery only through the ``Recovery`` and ``Recorder``
protocols (tests/test_layers.py).
"""
