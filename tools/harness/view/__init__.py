"""A run as people see it (docs/design.md §10 "Seeing the fleet"; docs/view.md): one scene,
drawn by Foxglove from a recording or live, or by the page in the browser.

``foxglove``: Foxglove's well-known schemas as JSON Schema, and their message builders.
``scene``: the Foxglove channels of a run (scene, plan, frames, log, statuses), built from
what the observer sees on the bus.
``live``: the sinks of the scene (the recorder's and the live Foxglove WebSocket server),
fanned out.
``webpage``: the page in the browser (``tools/web/``) and its server.
"""
