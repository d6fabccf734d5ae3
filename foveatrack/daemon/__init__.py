"""The real-time tracking daemon (``foveatrack daemon --config FILE``): Livox in, Pelco-D out.

* :mod:`foveatrack.daemon.config` -- ``load_config(path) -> DaemonConfig`` (TOML, validated)
* :mod:`foveatrack.daemon.runtime` -- ``Daemon(config, log_path=None, status=None, duration_s=None).run()``
* :mod:`foveatrack.daemon.support` -- ``Limits`` (the last safety gate), ``JsonLog``, ``StatusLine``,
  ``RecordingThread``
"""

from foveatrack.daemon.config import DaemonConfig, config_from_mapping, load_config
from foveatrack.daemon.runtime import Daemon
from foveatrack.daemon.support import Limits

__all__ = ["DaemonConfig", "Daemon", "Limits", "config_from_mapping", "load_config"]
