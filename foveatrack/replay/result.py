"""What a replay returns."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from foveatrack.tracker import TrackerConfig


@dataclass
class ReplayResult:
    """Per-frame arrays of the replay (``frames``), of the recording (``recorded``), truth (or None),
    the comparison and the metrics."""

    source: str
    path: str
    config: str
    frames: dict[str, np.ndarray]
    recorded: dict[str, np.ndarray] | None
    truth: dict[str, np.ndarray] | None
    comparison: dict = field(default_factory=dict)
    metrics: dict = field(default_factory=dict)
    recorded_metrics: dict = field(default_factory=dict)
    # Dead-reckoned (pan_deg, tilt_deg) once the head has settled after the last command sent
    # (2 s later): where the run left the head, by the tracker's own reckoning.
    final_pose_deg: tuple[float, float] | None = None
    # The tracker configuration the replay ran with (its dead band and tilt stops go on the plots).
    tracker_cfg: TrackerConfig | None = None
    # The multi-object tracker's tracks per frame ([tracker.sky] runs; TracksRecord), as replayed.
    tracks: list = field(default_factory=list)

    def summary(self) -> dict:
        return {"source": self.source, "path": self.path, "config": self.config, "frames": len(self.frames["t_end_s"]),
                "metrics": self.metrics, "comparison": self.comparison, "recorded_metrics": self.recorded_metrics,
                "final_pose_deg": None if self.final_pose_deg is None else list(self.final_pose_deg)}
