"""Replay: re-run the tracker over a recording (simulator or daemon) or a Livox ``.lvx`` file.

* :mod:`~foveatrack.replay.driver` -- replay as a driver: the recording's frames through the tracker
  and the command gate (``replay``, ``replay_recording``, ``replay_lvx``)
* :mod:`~foveatrack.replay.config` -- the tracker configuration and limits a recording ran with
* :mod:`~foveatrack.replay.recorded` -- a recording frame by frame, and the per-frame arrays
* :mod:`~foveatrack.replay.metrics` -- detection and tracking figures, the comparison with the recording
* :mod:`~foveatrack.replay.report` -- the text report and the trajectory export
"""

from foveatrack.replay.config import load_tracker_table, tracker_config
from foveatrack.replay.driver import replay, replay_lvx, replay_recording
from foveatrack.replay.metrics import _stats, bearing_metrics, compare, replay_metrics
from foveatrack.replay.report import export_replay_trajectory, format_report
from foveatrack.replay.result import ReplayResult

__all__ = ["ReplayResult", "bearing_metrics", "compare", "export_replay_trajectory", "format_report",
           "load_tracker_table", "replay", "replay_lvx", "replay_metrics", "replay_recording", "tracker_config",
           "_stats"]
