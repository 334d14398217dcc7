"""Drawing a world in Rerun: the parts :class:`user_peer.rerun_log.WorldLogger` is made of.

One module per concern, so a new robot kind or a new view is one module and not a thirtieth method:

- :mod:`.layout`: the views (blueprint), the timelines, the camera framing, and the entity layout;
- :mod:`.intake`: key parsing, message times, thinning and the stream-rate plots;
- :mod:`.canvas`: what every drawer shares: the recording, the current message's time, what was logged once;
- :mod:`.robots`: :class:`~.robots.RobotDrawing`, what the viewer knows about one robot;
- drawers, one per kind of thing: :mod:`.arm` (links, skeleton, flange), :mod:`.joints` (joint and wheel
  plots, feeding the arm's 3D pose), :mod:`.base` (mobile bases, their scans and sonar rings),
  :mod:`.maps` (occupancy grids and planned paths), :mod:`.objects` (scene objects and the static scene),
  :mod:`.labels` (ownership labels and the event log).
"""
