"""Open-loop tracking of a fixed sensor (no head): recordings made by someone else's lidar on a
mount that does not move.

* :mod:`~foveatrack.openloop.background` -- the static scene learned from the scans over time
* :mod:`~foveatrack.openloop.objects` -- a frame's foreground points clustered into objects
* :mod:`~foveatrack.openloop.tracker` -- acquisition without a hand-made D, then Algorithm 1
  (paper App. D.2) inside the chosen object's D
* :mod:`~foveatrack.openloop.reference` -- a reference trajectory and the error against it
* :mod:`~foveatrack.openloop.run` -- a source's frames through the tracker, the result and its CSV
"""

from foveatrack.openloop.tracker import OpenLoopConfig, OpenLoopTracker
from foveatrack.openloop.run import OpenLoopResult, track_source

__all__ = ["OpenLoopConfig", "OpenLoopResult", "OpenLoopTracker", "track_source"]
