"""The tracker configuration a recording ran with (its typed metadata,
:mod:`foveatrack.recording.run_meta`), or another ``[tracker]`` table on the recorded head by the rule
every driver applies (:meth:`foveatrack.tracker.TrackerConfig.with_head`)."""

from __future__ import annotations

import os
from collections.abc import Mapping

from foveatrack.recording.run_meta import RecordingMeta, recorded_limits
from foveatrack.tracker import TrackerConfig

__all__ = ["load_tracker_table", "recorded_limits", "tracker_config"]


def load_tracker_table(path: str | os.PathLike) -> dict:
    """The ``[tracker]`` table of a TOML file (a scene, a daemon config, or a bare tracker table)."""
    from foveatrack.config_util import as_table, read_toml

    data, _ = read_toml(path, "tracker config (--tracker-config)")
    return dict(as_table(data.get("tracker", data), "tracker", f"{path}"))


def tracker_config(meta: Mapping | RecordingMeta, table: dict | None = None,
                   where: str = "recorded [tracker]") -> TrackerConfig:
    """The effective tracker configuration of a recording (its typed metadata,
    :class:`foveatrack.recording.run_meta.RecordingMeta`, or the ``meta`` dict it is read from), or of
    another ``[tracker]`` ``table`` on the recording's head: the head's facts win by the rule every driver
    applies (:meth:`TrackerConfig.with_head`; a table that contradicts them is an error naming the key)."""
    rm = meta if isinstance(meta, RecordingMeta) else RecordingMeta.from_dict(meta)
    if table is None:
        return rm.tracker
    return TrackerConfig.from_mapping(dict(table), where=where).with_head(rm.head, table, where)
