"""The world on the bus (docs/design.md §3 queryables, §8 trust).

The world loop and its zenoh queryables (:mod:`.server`), a query as its callbacks take
it (:mod:`.requests`), who drives which robot (:mod:`.bindings`), motions in flight
(:mod:`.motions`), a slow world (:mod:`.delays`), the camera service (:mod:`.camera_desk`,
:mod:`.glances`, :mod:`.pending_pictures`) with its render processes (:mod:`.render_pool`
in the world's process group, :mod:`.render_worker` on the bus) and the hand client
(:mod:`.client`). It sits on :mod:`sim.physics`, :mod:`sim.camera` and
:mod:`sim.scenarios`.
"""
