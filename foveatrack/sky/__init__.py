"""Many objects in the sky seen from the moving head (issue 28, the perception half).

* :mod:`~foveatrack.sky.world_points` -- a frame's points in the world at each point's head pose
* :mod:`~foveatrack.sky.motion` -- the constant-velocity Kalman filter of one track (world frame)
* :mod:`~foveatrack.sky.tracks` -- background learned in the world, objects clustered, tracks
  associated by gated global nearest neighbour, confirmed and deleted, with stable ids
* :mod:`~foveatrack.sky.classify` -- drone, bird or clutter from what the lidar measures
* :mod:`~foveatrack.sky.attention` -- which track the fovea serves: threat score and revisits
* :mod:`~foveatrack.sky.controller` -- the head driven by the attention, Algorithms 1 and 2 inside
  each fixation (:class:`foveatrack.tracker.Tracker`'s)
* :mod:`~foveatrack.sky.metrics` -- GOSPA, continuity, id switches, false tracks, fovea shares

The clustering and the background (the static scene learned per direction as a range interval) are
the open-loop tracker's (:mod:`foveatrack.openloop.kernels`, :mod:`foveatrack.openloop.range_background`),
used here on world coordinates instead of the fixed sensor's.
"""
