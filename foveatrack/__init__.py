"""foveatrack: the tracker that runs on real hardware.

Frames, detection (paper Algorithm 1), control (Algorithm 2), speed-table calibration, trajectory
reconstruction, Livox input, recording and the daemon.  This package never imports ``sim``: the
tracker must run against a real Livox and a real head.  Only ``foveatrack.cli`` (the composition
root) reaches into ``sim``, lazily.
"""

__version__ = "0.1.0"
