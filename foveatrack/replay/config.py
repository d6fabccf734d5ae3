"""The tracker configuration a recording ran with, and the gate's limits it recorded: rebuilt
for replay by the rule every driver applies (:meth:`foveatrack.tracker.TrackerConfig.with_head`)."""

from __future__ import annotations

import os
from dataclasses import replace

from foveatrack.errors import UserError
from foveatrack.gate import Limits
from foveatrack.tracker import TrackerConfig


def load_tracker_table(path: str | os.PathLike) -> dict:
    """The ``[tracker]`` table of a TOML file (a scene, a daemon config, or a bare tracker table)."""
    from foveatrack.config_util import as_table, read_toml

    data, _ = read_toml(path, "tracker config (--tracker-config)")
    return dict(as_table(data.get("tracker", data), "tracker", f"{path}"))


def _overrides(meta: dict) -> dict:
    src = meta.get("source")
    if "tracker_overrides" in meta:  # written by the daemon and by the simulator
        return {k: tuple(v) if isinstance(v, list) else v for k, v in meta["tracker_overrides"].items()}
    if src == "simulator":  # recordings made before the simulator wrote its overrides
        from gimbal.pelco import frame_time_s
        from gimbal.pts303h import HeadParams

        g = meta["gimbal"]
        params = HeadParams.for_family(g["family"])
        tilt0 = min(max(g["tilt0_deg"], params.tilt_min_deg), params.tilt_max_deg)
        return {"pan0_deg": g["pan0_deg"], "tilt0_deg": tilt0,
                "tilt_limits_deg": (params.tilt_min_deg, params.tilt_max_deg),
                "latency_s": frame_time_s("D", g["baud"]), "send_delay_s": g["send_delay_s"]}
    raise UserError(f"recording source {src!r} is not 'simulator' or 'daemon'")


class _RecordedHead:
    """The head's facts as a recording gives them (its ``tracker_overrides``), for
    :meth:`TrackerConfig.with_head`."""

    def __init__(self, values: dict):
        self._values = {k: tuple(v) if isinstance(v, list) else v for k, v in values.items()}

    def tracker_values(self) -> dict:
        return dict(self._values)


def tracker_config(meta: dict, table: dict | None = None, where: str = "recorded [tracker]") -> TrackerConfig:
    """The effective tracker configuration of a recording, or of another ``[tracker]`` ``table`` on the
    recording's head: the head's facts win by the rule every driver applies (:meth:`TrackerConfig.with_head`;
    a table that contradicts them is an error naming the key).  Without ``table`` the recorded table and
    the head values recorded with it rebuild what ran (in daemon recordings made before that rule, a
    [tracker] head key had won over [head], and the recording left that key out of its overrides)."""
    head = _RecordedHead(_overrides(meta))
    if table is None:
        return replace(TrackerConfig.from_mapping(dict(meta.get("tracker_table", {})), where=where),
                       **head.tracker_values())
    return TrackerConfig.from_mapping(dict(table), where=where).with_head(head, table, where)


def recorded_limits(meta: dict) -> Limits | None:
    """The gate's limits as the daemon or the simulator recorded them (None where none were recorded:
    a scene without [gate], older recordings; their commands pass the gate unchanged)."""
    if not meta.get("limits"):
        return None
    L = dict(meta["limits"])
    L["tilt_limits_deg"] = tuple(L["tilt_limits_deg"])
    return Limits(**L)
