"""A recording's metadata as one typed object: the configuration that ran, and where the run came from.

The simulator (``sim.recorder``) and the daemon (:mod:`foveatrack.daemon.runtime`) both build a
:class:`RecordingMeta` from the objects that run -- the tracker's :class:`~foveatrack.tracker.TrackerConfig`
after the head's facts were applied, the speed table, the gate's limits -- and write :meth:`RecordingMeta.to_dict`
as the recording's ``meta`` (:class:`foveatrack.recording.RecordingWriter`).  Replay and the Foxglove view
read it back with :meth:`RecordingMeta.from_dict`; the tracker is rebuilt from its recorded table
(:meth:`TrackerConfig.to_mapping`, every setting) and equals the one that ran.  No raw ``[tracker]``
table travels beside it: a run whose configuration was changed in code (a Monte-Carlo gain, a study's
frame window) records what it ran, not what its scene file said (issue 25).

Keys of ``to_dict`` (flat, JSON-plain):

* both: ``source`` ("simulator" | "daemon"), ``tracker`` (the effective tracker table), ``head_values``
  (the tracker keys the head's facts set, :meth:`gimbal.head_facts.HeadFacts.tracker_values`: kept by a
  replay with another ``[tracker]`` table), ``speed_table``, ``limits`` (the gate's; absent: commands
  passed unchanged), ``tracker_t0_s``, ``point_rate_hz``, ``half_fov_deg`` (the simulator's), ``sky``
  (only where the multi-object tracker ran: its effective ``[tracker.sky]`` table,
  :meth:`foveatrack.sky.controller.SkyController.sky_table`, which replay rebuilds it from)
* simulator (:class:`SimulatorOrigin`): ``scene_name``, ``scene_path``, ``scene_text``, ``seed``,
  ``effects``, ``gimbal`` (the scene's ``[gimbal]`` settings)
* daemon (:class:`DaemonOrigin`): ``config_path``, ``config_text``, ``head``, ``lidar`` (its
  :class:`~foveatrack.device_config.HeadConfig` and :class:`~foveatrack.device_config.LidarConfig`)

Recordings written before this (a ``tracker_table`` key: the raw table, the head's ``tracker_overrides``
and, from some point on, ``tracker_effective`` beside it) are read by one path, :func:`from_legacy_dict`,
which rebuilds their tracker exactly as replay always did.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields, replace
from typing import Any, ClassVar

from foveatrack.device_config import HeadConfig, LidarConfig
from foveatrack.errors import UserError
from foveatrack.gate import Limits
from foveatrack.speed_table import SpeedTable
from foveatrack.tracker import TrackerConfig


def _tuples(d: Mapping) -> dict:
    """JSON lists back to the tuples the dataclasses hold."""
    return {k: tuple(v) if isinstance(v, list) else v for k, v in d.items()}


def _lists(d: Mapping) -> dict:
    return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}


@dataclass(frozen=True)
class SimulatorOrigin:
    """Where a simulator run came from: its scene (name, file, text as read), seed, effects and
    ``[gimbal]`` settings (``sim.scene.GimbalSpec`` as a table: the simulator's own type)."""
    source: ClassVar[str] = "simulator"
    scene_name: str
    scene_path: str | None
    scene_text: str | None
    seed: int
    effects: tuple[str, ...]
    gimbal: Mapping[str, Any]

    def to_dict(self) -> dict:
        return {"scene_name": self.scene_name, "scene_path": self.scene_path, "scene_text": self.scene_text,
                "seed": self.seed, "effects": sorted(self.effects), "gimbal": dict(self.gimbal)}

    @classmethod
    def from_dict(cls, d: Mapping) -> "SimulatorOrigin":
        return cls(d.get("scene_name"), d.get("scene_path"), d.get("scene_text"), d.get("seed"),
                   tuple(d.get("effects") or ()), dict(d.get("gimbal") or {}))


@dataclass(frozen=True)
class DaemonOrigin:
    """Where a daemon run came from: its config file (path, text as read), head and lidar settings."""
    source: ClassVar[str] = "daemon"
    config_path: str | None
    config_text: str | None
    head: HeadConfig | Mapping[str, Any]
    lidar: LidarConfig | Mapping[str, Any]

    def to_dict(self) -> dict:
        plain = lambda v: _lists(asdict(v) if not isinstance(v, Mapping) else v)   # noqa: E731
        return {"config_path": self.config_path, "config_text": self.config_text,
                "head": plain(self.head), "lidar": plain(self.lidar)}

    @classmethod
    def from_dict(cls, d: Mapping) -> "DaemonOrigin":
        return cls(d.get("config_path"), d.get("config_text"), _typed(HeadConfig, d.get("head")),
                   _typed(LidarConfig, d.get("lidar")))


def _typed(cls, d):
    """The dataclass from its recorded table; the table itself where it does not fit the class as it is
    now (a recording of an older daemon: fields renamed or added since)."""
    if not isinstance(d, Mapping):
        return {}
    if set(d) <= {f.name for f in fields(cls)}:
        try:
            return cls(**_tuples(d))
        except TypeError:
            pass
    return dict(d)


@dataclass(frozen=True)
class RecordingMeta:
    """The metadata of one recording (module docstring).

    tracker : the configuration that ran, every setting (the head's facts applied)
    head_values : the tracker keys the head's facts set (``HeadFacts.tracker_values()``)
    origin : :class:`SimulatorOrigin` or :class:`DaemonOrigin`
    """
    tracker: TrackerConfig
    head_values: Mapping[str, Any]
    speed_table: SpeedTable
    limits: Limits | None
    origin: SimulatorOrigin | DaemonOrigin
    tracker_t0_s: float = 0.0
    point_rate_hz: float | None = None
    half_fov_deg: float | None = None
    #: the multi-object tracker's effective ``[tracker.sky]`` table where it ran (None: the paper's tracker)
    sky: Mapping[str, Any] | None = None
    #: a recording of the earlier form (:func:`from_legacy_dict`), and its ``tracker_effective`` where it
    #: has one (what replay checks its rebuilt configuration against)
    legacy: bool = False
    legacy_effective: Mapping[str, Any] | None = None

    @property
    def source(self) -> str:
        return self.origin.source

    @property
    def head(self) -> "RecordedHead":
        """The recorded head's facts, for :meth:`TrackerConfig.with_head` (replay with another table)."""
        return RecordedHead(self.head_values)

    def to_dict(self) -> dict:
        d = {"source": self.source, "tracker": self.tracker.to_mapping(), "head_values": _lists(self.head_values),
             "speed_table": self.speed_table.to_dict(), "tracker_t0_s": self.tracker_t0_s,
             "point_rate_hz": self.point_rate_hz, **self.origin.to_dict()}
        if self.half_fov_deg is not None:
            d["half_fov_deg"] = self.half_fov_deg
        if self.limits is not None:
            d["limits"] = _lists(asdict(self.limits))
        if self.sky is not None:
            d["sky"] = json.loads(json.dumps(self.sky))
        return d

    @classmethod
    def from_dict(cls, meta: Mapping, where: str = "recording") -> "RecordingMeta":
        """The typed metadata of a recording's ``meta`` dict, of this form or an earlier one
        (:func:`from_legacy_dict`); a UserError naming ``where`` and what is missing otherwise."""
        try:
            if "tracker" not in meta or "tracker_table" in meta:
                return from_legacy_dict(meta, where)
            src = meta.get("source")
            if src not in (SimulatorOrigin.source, DaemonOrigin.source):
                raise UserError(f"{where}: {_not_replayable(src)}")
            for k in ("tracker", "head_values"):
                if not isinstance(meta.get(k), Mapping):
                    raise UserError(f"{where}: the recording's metadata has no {k!r} table")
            return cls(TrackerConfig.from_mapping(meta["tracker"], where=f"{where}: recorded [tracker]"),
                       _tuples(meta["head_values"]), _speed_table(meta, where), recorded_limits(meta),
                       _origin(meta), float(meta.get("tracker_t0_s", 0.0)), meta.get("point_rate_hz"),
                       meta.get("half_fov_deg"), _sky(meta, where))
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            # a metadata dict no foveatrack run wrote (a hand-made or damaged one)
            raise UserError(f"{where}: the recording's metadata does not hold a run's configuration "
                            f"({type(exc).__name__}: {exc})") from None

    def tracker_as_recorded(self) -> bool | None:
        """The rebuilt configuration is the one the recording says ran (JSON-normalised: tuples as
        lists): the table of this form, or an earlier recording's ``tracker_effective``; None for an
        earlier recording without one (it does not say)."""
        if self.legacy:
            if self.legacy_effective is None:
                return None
            return json.loads(json.dumps(self.tracker.effective())) == self.legacy_effective
        return TrackerConfig.from_mapping(json.loads(json.dumps(self.tracker.to_mapping()))) == self.tracker


class RecordedHead:
    """A recorded head's facts as :meth:`TrackerConfig.with_head` reads them (``tracker_values``)."""

    def __init__(self, values: Mapping):
        self._values = _tuples(values)

    def tracker_values(self) -> dict:
        return dict(self._values)


def _speed_table(meta: Mapping, where: str) -> SpeedTable:
    if "speed_table" not in meta:
        raise UserError(f"{where}: the recording's metadata has no 'speed_table'")
    return SpeedTable.from_dict(meta["speed_table"], where=f"{where}: recorded speed table")


def _sky(meta: Mapping, where: str) -> dict | None:
    sky = meta.get("sky")
    if sky is not None and not isinstance(sky, Mapping):
        raise UserError(f"{where}: the recording's 'sky' (the multi-object tracker's table) is not a table: {sky!r}")
    return None if sky is None else dict(sky)


def _origin(meta: Mapping) -> SimulatorOrigin | DaemonOrigin:
    return SimulatorOrigin.from_dict(meta) if meta.get("source") == SimulatorOrigin.source else DaemonOrigin.from_dict(meta)


def recorded_limits(meta: Mapping) -> Limits | None:
    """The gate's limits as the daemon or the simulator recorded them (None where none were recorded:
    a scene without [gate], older recordings; their commands pass the gate unchanged)."""
    if not meta.get("limits"):
        return None
    return Limits(**_tuples(meta["limits"]))


# ----------------------------------------------------------------------------------- the earlier form
def _legacy_head_values(meta: Mapping) -> dict:
    """The head's tracker keys of a recording of the earlier form: its ``tracker_overrides``, or for
    simulator recordings made before those were written, what the simulator set from ``[gimbal]``."""
    if "tracker_overrides" in meta:  # written by the daemon and by the simulator
        return _tuples(meta["tracker_overrides"])
    if meta.get("source") == "simulator":
        from gimbal.pelco import frame_time_s
        from gimbal.pts303h import HeadParams

        g = meta["gimbal"]
        params = HeadParams.for_family(g["family"])
        tilt0 = min(max(g["tilt0_deg"], params.tilt_min_deg), params.tilt_max_deg)
        return {"pan0_deg": g["pan0_deg"], "tilt0_deg": tilt0,
                "tilt_limits_deg": (params.tilt_min_deg, params.tilt_max_deg),
                "latency_s": frame_time_s("D", g["baud"]), "send_delay_s": g["send_delay_s"]}
    raise UserError(_not_replayable(meta.get("source")))


def _not_replayable(source) -> str:
    """Why a recording of another ``source`` has no closed loop to re-run, and what to do with it."""
    if source == "openloop":
        # (the track command's own recording: replay said only "source 'openloop' is not ...", a
        # user's audit, where track pointed to replay)
        return ("a recording `foveatrack track --record` made (source 'openloop'): its tracks are that run's "
                "output, with no head loop to re-run; run `foveatrack track` on its source again (another "
                "--config), open it in Foxglove, or `foveatrack export` its points")
    return f"recording source {source!r} is not 'simulator' or 'daemon' (what replay re-runs)"


def from_legacy_dict(meta: Mapping, where: str = "recording") -> RecordingMeta:
    """The one reader of the earlier metadata form (recordings made before :class:`RecordingMeta`: the
    regression fixtures, ``tests/corpus``, recordings in the field).  Their tracker is rebuilt as replay
    always rebuilt it: the raw ``[tracker]`` table with the head values recorded beside it set on top (in
    daemon recordings made before :meth:`TrackerConfig.with_head`, a [tracker] head key had won over
    [head], and the recording left that key out of its overrides)."""
    try:
        head_values = _legacy_head_values(meta)
    except UserError as exc:
        raise UserError(f"{where}: {exc}") from None
    table = dict(meta.get("tracker_table") or {})
    tracker = replace(TrackerConfig.from_mapping(table, where=f"{where}: recorded [tracker]"), **head_values)
    return RecordingMeta(tracker, head_values, _speed_table(meta, where), recorded_limits(meta), _origin(meta),
                         float(meta.get("tracker_t0_s", 0.0)), meta.get("point_rate_hz"), meta.get("half_fov_deg"),
                         legacy=True, legacy_effective=meta.get("tracker_effective"))


def recorded_tracker(meta: Mapping | None) -> TrackerConfig | None:
    """The tracker configuration a recording's ``meta`` names, or None where it names none that reads
    (a meta of a caller's own, a damaged one): for drawings (:mod:`foveatrack.recording.foxglove_view`),
    which must not fail a recording."""
    if not meta:
        return None
    try:
        return RecordingMeta.from_dict(meta).tracker
    except (UserError, KeyError, TypeError, ValueError):
        pass
    table = meta.get("tracker_table")      # the earlier form without the rest of a run's metadata
    try:
        return TrackerConfig.from_mapping(table) if isinstance(table, Mapping) else None
    except UserError:
        return None
