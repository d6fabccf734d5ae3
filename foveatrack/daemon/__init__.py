"""The real-time tracking daemon (``foveatrack daemon --config FILE``): Livox in, Pelco-D out.

* :mod:`foveatrack.device_config` -- ``load_config(path) -> DaemonConfig`` (TOML, validated)
* :mod:`foveatrack.daemon.runtime` -- ``Daemon(config, log_path=None, status=None, duration_s=None).run()``
  (its roles: ``lifecycle``, ``frame_loop``, ``head_pose``, ``watchdog``, ``record_queue``, ``status_display``,
  ``run_stats``, ``operator``; the lidar's thread is ``receiver``, the head's pose check ``pose_guard``)
* :mod:`foveatrack.daemon.support` -- ``JsonLog``, ``StatusLine``, ``RecordingThread``
* ``Limits`` (the last safety gate) is :mod:`foveatrack.gate`'s, shared with the simulator and replay
"""

from foveatrack.device_config import DaemonConfig, config_from_mapping, load_config
from foveatrack.daemon.runtime import Daemon
from foveatrack.gate import Limits

__all__ = ["DaemonConfig", "Daemon", "Limits", "config_from_mapping", "load_config"]
