"""The typed records of a recording: one class per channel, written and read by the same code.

Every driver writes these (the simulator, the daemon) and replay reads them back; a record's JSON
field names are the file format (unchanged since format version 1, so older recordings read), while
the attributes say what a value is -- ``true_`` for simulation truth, ``est_`` for what the tracker
believes (its dead-reckoned head pose, its reconstructed target):

=====================  ==============  =====================================================
class                  channel         what
=====================  ==============  =====================================================
DetectionRecord        /detections     Algorithm 1 on a frame (lidar frame) and the tracker's state
HeadEstimateRecord     /head           the tracker's estimate: head pose and target in the world
CommandRecord          /commands       a command as written to the head (Pelco bytes), and why
                                       the gate changed it
TruthRecord            /truth          simulation only: the true head pose and target
ObjectTruthRecord      /truth_objects  simulation only, multi-object scenes: every object's truth
TracksRecord           /tracks         the multi-object tracker (``[tracker.sky]``): every track
=====================  ==============  =====================================================

The IMU samples fed to the tracker (``/imu``) are arrays, not a JSON record:
:class:`foveatrack.recording.format.ImuSamples`, written by :func:`write_tracker_frame`.

``from_json`` takes a record as read (missing keys of older files become None / defaults; a field
of the wrong type, from a damaged or crafted file, raises :class:`RecordError` naming it);
``to_json`` gives the dict to write, its keys in the order the writers have always used (a run
records the same bytes as before).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from foveatrack.fixed_order import floats3
from foveatrack.recording.format import COMMANDS, DETECTIONS, HEAD, TRACKS, TRUTH, TRUTH_OBJECTS


def ns(t_s: float) -> int:
    """Seconds -> the integer nanoseconds records are stamped with."""
    return int(round(t_s * 1e9))


def _finite_or_none(v):
    """JSON has no NaN: a missing or non-finite float is recorded as null."""
    return None if v is None or (isinstance(v, float) and not math.isfinite(v)) else v


def _xyz(v):
    return None if v is None else list(map(float, v))


def _nan(v) -> float:
    return math.nan if v is None else float(v)


class RecordError(ValueError):
    """A record read back whose field is missing or not of its type (a damaged or crafted file): the
    reader's caller names the file and the record."""


_MISSING = object()


def _field(r: dict, key: str, default=_MISSING):
    if not isinstance(r, dict):
        raise RecordError(f"not a JSON object but {type(r).__name__}")
    if key in r:
        return r[key]
    if default is _MISSING:
        raise RecordError(f"no field {key!r}")
    return default


def _is_num(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _int_f(r: dict, key: str, default=_MISSING, nullable: bool = False) -> int | None:
    v = _field(r, key, default)
    if v is None and nullable:
        return None
    if not isinstance(v, int) or isinstance(v, bool):
        raise RecordError(f"field {key!r}: {v!r} is not a whole number")
    return v


def _num_f(r: dict, key: str, nan_if_none: bool = False) -> float | None:
    """An optional number (None stays None, or NaN with ``nan_if_none``)."""
    v = _field(r, key, None)
    if v is None:
        return math.nan if nan_if_none else None
    if not _is_num(v):
        raise RecordError(f"field {key!r}: {v!r} is not a number")
    return v if not nan_if_none else float(v)


def _str_f(r: dict, key: str) -> str | None:
    v = _field(r, key, None)
    if v is not None and not isinstance(v, str):
        raise RecordError(f"field {key!r}: {v!r} is not a string")
    return v


def _bool_f(r: dict, key: str, default=None) -> bool | None:
    v = _field(r, key, default)
    if v is not None and not isinstance(v, bool):
        raise RecordError(f"field {key!r}: {v!r} is not true or false")
    return v


def _vec_f(r: dict, key: str, n: int = 3, default=None) -> tuple | None:
    v = _field(r, key, default)
    if v is None:
        return None
    if not isinstance(v, (list, tuple)) or len(v) != n or not all(_is_num(x) or x is None for x in v):
        raise RecordError(f"field {key!r}: {v!r} is not {n} numbers")
    return tuple(v)


@dataclass(frozen=True)
class DetectionRecord:
    """Algorithm 1's output for frame ``frame_id`` (``t_ns`` = frame end): the target's median point
    ``xyz_m`` [m, lidar frame] or None, its time and bearing, the tracker state and the angular errors
    [deg] the controller saw (None when nothing was detected)."""

    CHANNEL = DETECTIONS
    t_ns: int
    frame_id: int
    detected: bool
    xyz_m: tuple | None = None
    n_points: int = 0
    t_s: float | None = None
    az_deg: float | None = None
    el_deg: float | None = None
    state: str | None = None
    error_pan_deg: float | None = None
    error_tilt_deg: float | None = None

    @classmethod
    def from_output(cls, t_ns: int, frame_id: int, out) -> "DetectionRecord":
        """From a :class:`foveatrack.tracker.TrackOutput`."""
        d = out.detection
        state = str(getattr(out.state, "value", out.state))
        errors = _finite_or_none(out.error_pan_deg), _finite_or_none(out.error_tilt_deg)
        if d is None:
            return cls(int(t_ns), int(frame_id), False, None, 0, None, None, None, state, *errors)
        return cls(int(t_ns), int(frame_id), True, tuple(floats3(d.xyz)), int(d.n_points), float(d.t_s),
                   float(d.az_deg), float(d.el_deg), state, *errors)

    def to_json(self) -> dict:
        return {"frame_index": self.frame_id, "detected": self.detected, "xyz_m": _xyz(self.xyz_m),
                "n_points": self.n_points, "t_s": self.t_s, "az_deg": self.az_deg, "el_deg": self.el_deg,
                "state": self.state, "error_pan_deg": self.error_pan_deg, "error_tilt_deg": self.error_tilt_deg}

    @classmethod
    def from_json(cls, r: dict) -> "DetectionRecord":
        return cls(_int_f(r, "t_ns"), _int_f(r, "frame_index", -1), _bool_f(r, "detected", False),
                   _vec_f(r, "xyz_m"), _int_f(r, "n_points", 0), _num_f(r, "t_s"), _num_f(r, "az_deg"),
                   _num_f(r, "el_deg"), _str_f(r, "state"), _num_f(r, "error_pan_deg"), _num_f(r, "error_tilt_deg"))


@dataclass(frozen=True)
class HeadEstimateRecord:
    """What the tracker believes at frame end: the head's dead-reckoned pose [deg] (pan + = left, tilt
    + = up) with its 1-sigma, and the target reconstructed in the world [m] (None without one)."""

    CHANNEL = HEAD
    t_ns: int
    frame_id: int
    est_pan_deg: float
    est_tilt_deg: float
    est_sigma_pan_deg: float | None = None
    est_sigma_tilt_deg: float | None = None
    est_target_world_m: tuple | None = None
    est_target_world_sigma_m: float | None = None

    @classmethod
    def from_output(cls, t_ns: int, frame_id: int, out) -> "HeadEstimateRecord":
        return cls(int(t_ns), int(frame_id), float(out.head_pan_deg), float(out.head_tilt_deg),
                   out.head_sigma_pan_deg, out.head_sigma_tilt_deg,
                   None if out.world_xyz is None else tuple(floats3(out.world_xyz)),
                   _finite_or_none(out.world_sigma_m))

    def to_json(self) -> dict:
        return {"pan_deg": float(self.est_pan_deg), "tilt_deg": float(self.est_tilt_deg), "frame_id": self.frame_id,
                "sigma_pan_deg": self.est_sigma_pan_deg, "sigma_tilt_deg": self.est_sigma_tilt_deg,
                "world_xyz_m": _xyz(self.est_target_world_m), "world_sigma_m": self.est_target_world_sigma_m}

    @classmethod
    def from_json(cls, r: dict) -> "HeadEstimateRecord":
        return cls(_int_f(r, "t_ns"), _int_f(r, "frame_id", -1), _num_f(r, "pan_deg", True),
                   _num_f(r, "tilt_deg", True), _num_f(r, "sigma_pan_deg"), _num_f(r, "sigma_tilt_deg"),
                   _vec_f(r, "world_xyz_m"), _num_f(r, "world_sigma_m"))


@dataclass(frozen=True)
class CommandRecord:
    """A command as written to the head: ``raw`` the Pelco bytes, ``t_ns`` the send time the dead
    reckoning used, the decoded speeds, and from the gate (:mod:`foveatrack.gate`) why it differs
    from the tracker's (``limited``, with ``tracker_command``).  The daemon adds ``source``
    (tracker, watchdog, shutdown), ``written`` (False: the link failed, the head never got it) and
    ``host_written_s`` (monotonic host time of the write)."""

    CHANNEL = COMMANDS
    t_ns: int
    raw: bytes
    pan_dir: int
    pan_byte: int
    tilt_dir: int
    tilt_byte: int
    frame_id: int | None = None
    source: str | None = None
    send_t_s: float | None = None
    written: bool | None = None
    host_written_s: float | None = None
    limited: tuple[str, ...] = field(default=())
    tracker_command: tuple | None = None

    @property
    def command(self):
        from foveatrack.control import HeadCommand

        return HeadCommand(self.pan_dir, self.pan_byte, self.tilt_dir, self.tilt_byte)

    @property
    def speeds(self) -> tuple:
        return (self.pan_dir, self.pan_byte, self.tilt_dir, self.tilt_byte)

    @property
    def from_tracker(self) -> bool:
        return self.source in (None, "tracker")

    @property
    def reached_head(self) -> bool:
        return self.written is not False

    @property
    def send_time_s(self) -> float:
        return self.send_t_s if self.send_t_s is not None else self.t_ns * 1e-9

    def to_json(self) -> dict:
        r = {"raw_hex": bytes(self.raw).hex(), "frame_id": self.frame_id}
        for k in ("source", "send_t_s", "written", "host_written_s"):
            v = getattr(self, k)
            if v is not None:
                r[k] = v
        r.update(pan_dir=self.pan_dir, pan_byte=self.pan_byte, tilt_dir=self.tilt_dir, tilt_byte=self.tilt_byte)
        if self.limited:
            r["limited"] = list(self.limited)
            r["tracker_command"] = None if self.tracker_command is None else list(self.tracker_command)
        return r

    @classmethod
    def from_json(cls, r: dict) -> "CommandRecord":
        raw = _str_f(r, "raw_hex") or ""
        try:
            raw_b = bytes.fromhex(raw)
        except ValueError:
            raise RecordError(f"field 'raw_hex': {raw[:40]!r} is not hexadecimal") from None
        limited = _field(r, "limited", ())
        if not isinstance(limited, (list, tuple)) or not all(isinstance(x, str) for x in limited):
            raise RecordError(f"field 'limited': {limited!r} is not a list of names")
        tc = _field(r, "tracker_command", None)
        if tc is not None and (not isinstance(tc, (list, tuple)) or len(tc) != 4
                               or not all(isinstance(x, int) and not isinstance(x, bool) for x in tc)):
            raise RecordError(f"field 'tracker_command': {tc!r} is not 4 whole numbers")
        return cls(_int_f(r, "t_ns"), raw_b, *(_int_f(r, k, None, True) for k in ("pan_dir", "pan_byte", "tilt_dir",
                                                                                "tilt_byte")),
                   _int_f(r, "frame_id", None, True), _str_f(r, "source"), _num_f(r, "send_t_s"),
                   _bool_f(r, "written"), _num_f(r, "host_written_s"), tuple(limited),
                   None if tc is None else tuple(tc))


@dataclass(frozen=True)
class TruthRecord:
    """Simulation truth at frame mid (``t_ns`` = frame end): the head's true pose [deg], the target's
    true position [m, world], the true off-axis error [deg] and the points that hit the target."""

    CHANNEL = TRUTH
    t_ns: int
    frame_id: int
    true_pan_deg: float
    true_tilt_deg: float
    true_target_world_m: tuple
    true_error_deg: float | None
    points_on_target: int

    def to_json(self) -> dict:
        return {"frame_id": self.frame_id, "pan_deg": self.true_pan_deg, "tilt_deg": self.true_tilt_deg,
                "target_xyz_m": _xyz(self.true_target_world_m), "true_error_deg": _finite_or_none(self.true_error_deg),
                "points_on_target": self.points_on_target}

    @classmethod
    def from_json(cls, r: dict) -> "TruthRecord":
        return cls(_int_f(r, "t_ns"), _int_f(r, "frame_id", -1), _num_f(r, "pan_deg", True),
                   _num_f(r, "tilt_deg", True), _vec_f(r, "target_xyz_m", 3, (math.nan,) * 3),
                   _num_f(r, "true_error_deg"), _int_f(r, "points_on_target", 0))


@dataclass(frozen=True)
class ObjectTruthRecord:
    """Simulation truth of one object of a multi-object scene at frame mid (``t_ns`` = frame end):
    its id and class ("drone", "bird", "tree", "clutter": a stray near return), position [m] and
    velocity [m/s] in the world, size [m] (a drone's span, a bird's wingspan, a crown's diameter)
    and the rays of the frame that hit it (before the effects act)."""

    CHANNEL = TRUTH_OBJECTS
    t_ns: int
    frame_id: int
    id: str
    cls: str
    true_world_m: tuple
    true_velocity_m_s: tuple
    size_m: float
    rays_hit: int

    def to_json(self) -> dict:
        return {"frame_id": self.frame_id, "id": self.id, "class": self.cls, "xyz_m": _xyz(self.true_world_m),
                "velocity_m_s": _xyz(self.true_velocity_m_s), "size_m": self.size_m, "rays_hit": self.rays_hit}

    @classmethod
    def from_json(cls, r: dict) -> "ObjectTruthRecord":
        nan3 = (math.nan,) * 3
        xyz, vel = _vec_f(r, "xyz_m", 3, nan3) or nan3, _vec_f(r, "velocity_m_s", 3, nan3) or nan3
        return cls(_int_f(r, "t_ns"), _int_f(r, "frame_id", -1), str(r.get("id", "")), str(r.get("class", "")),
                   tuple(math.nan if x is None else x for x in xyz), tuple(math.nan if x is None else x for x in vel),
                   _nan(r.get("size_m")), _int_f(r, "rays_hit", 0))


def _ints_f(r: dict, key: str) -> tuple:
    v = _field(r, key, [])
    if not isinstance(v, (list, tuple)) or not all(isinstance(x, int) and not isinstance(x, bool) for x in v):
        raise RecordError(f"field {key!r}: {v!r} is not a list of whole numbers")
    return tuple(v)


@dataclass(frozen=True)
class TrackEntry:
    """One track as a frame of the multi-object tracker left it (:class:`foveatrack.sky.tracks.TrackView`):
    id, confirmed, label (after the classifier's wait) and what it looks like this frame, position [m]
    and velocity [m/s] in the world, hit this frame, in the lidar's field, threat score (confirmed
    tracks; None otherwise)."""
    id: int
    confirmed: bool
    label: str
    looks_like: str
    xyz_m: tuple
    velocity_m_s: tuple
    hit: bool
    in_view: bool
    score: float | None = None

    def to_json(self) -> dict:
        return {"id": self.id, "confirmed": self.confirmed, "label": self.label, "looks_like": self.looks_like,
                "xyz_m": _xyz(self.xyz_m), "velocity_m_s": _xyz(self.velocity_m_s), "hit": self.hit,
                "in_view": self.in_view, "score": self.score}

    @classmethod
    def from_json(cls, r: dict) -> "TrackEntry":
        xyz, vel = _vec_f(r, "xyz_m", default=_MISSING), _vec_f(r, "velocity_m_s", default=_MISSING)
        return cls(_int_f(r, "id"), bool(_bool_f(r, "confirmed", False)), _str_f(r, "label") or "unknown",
                   _str_f(r, "looks_like") or "unknown", xyz, vel, bool(_bool_f(r, "hit", False)),
                   bool(_bool_f(r, "in_view", True)), _num_f(r, "score"))


@dataclass(frozen=True)
class TracksRecord:
    """Every track of the multi-object tracker after frame ``frame_id`` (``t_ns`` = frame end), and the
    fovea's schedule: the track it served this frame, the one it serves next, the operator's pin, the
    confirmed tracks inside it; the frame's points, foreground points and objects; the ids confirmed
    and deleted this frame (issue 28, :class:`foveatrack.sky.controller.SkyControlOutput`)."""

    CHANNEL = TRACKS
    t_ns: int
    frame_id: int
    tracks: tuple
    fixated: int | None = None
    next_target: int | None = None
    pinned: int | None = None
    in_fovea: tuple = ()
    n_points: int = 0
    n_foreground: int = 0
    n_objects: int = 0
    confirmed_now: tuple = ()
    deleted_now: tuple = ()

    @classmethod
    def from_output(cls, t_ns: int, frame_id: int, out) -> "TracksRecord":
        """From a :class:`foveatrack.sky.controller.SkyControlOutput`."""
        sky = out.sky
        opt = lambda v: None if v is None else int(v)      # noqa: E731
        tracks = tuple(TrackEntry(int(v.track_id), bool(v.confirmed), str(v.label), str(v.looks_like),
                                  tuple(floats3(v.xyz_m)), tuple(floats3(v.velocity_m_s)), bool(v.hit),
                                  bool(v.in_view), None if v.track_id not in out.scores
                                  else float(out.scores[v.track_id]))
                       for v in sky.tracks)
        return cls(int(t_ns), int(frame_id), tracks, opt(out.fixated), opt(out.next_target), opt(out.pinned),
                   tuple(int(i) for i in out.in_fovea), int(sky.n_points), int(sky.n_foreground),
                   int(sky.n_objects), tuple(int(i) for i in sky.confirmed_now),
                   tuple(int(i) for i in sky.deleted_now))

    def to_json(self) -> dict:
        return {"frame_id": self.frame_id, "fixated": self.fixated, "next_target": self.next_target,
                "pinned": self.pinned, "in_fovea": list(self.in_fovea), "n_points": self.n_points,
                "n_foreground": self.n_foreground, "n_objects": self.n_objects,
                "confirmed_now": list(self.confirmed_now), "deleted_now": list(self.deleted_now),
                "tracks": [t.to_json() for t in self.tracks]}

    @classmethod
    def from_json(cls, r: dict) -> "TracksRecord":
        tracks = _field(r, "tracks", [])
        if not isinstance(tracks, list):
            raise RecordError(f"field 'tracks': {tracks!r} is not a list")
        entries = []
        for k, t in enumerate(tracks):
            try:
                entries.append(TrackEntry.from_json(t))
            except RecordError as exc:
                raise RecordError(f"tracks[{k}]: {exc}") from None
        return cls(_int_f(r, "t_ns"), _int_f(r, "frame_id", -1), tuple(entries),
                   _int_f(r, "fixated", None, nullable=True), _int_f(r, "next_target", None, nullable=True),
                   _int_f(r, "pinned", None, nullable=True), _ints_f(r, "in_fovea"), _int_f(r, "n_points", 0),
                   _int_f(r, "n_foreground", 0), _int_f(r, "n_objects", 0), _ints_f(r, "confirmed_now"),
                   _ints_f(r, "deleted_now"))


def write_record(writer, rec) -> None:
    """Write a typed record on its channel."""
    writer.write(rec.CHANNEL, rec.t_ns, rec.to_json())


def write_tracker_frame(writer, frame_id: int, frame, out, imu=None) -> int:
    """Record one frame and the tracker's output for it (points, detection, head estimate, and every
    track where the multi-object tracker ran), as every driver does; returns the frame-end time [ns].
    Commands and truth each driver writes itself.

    ``imu``: the samples the driver gave ``Tracker.on_imu`` before the frame, ``(t_s, gyro_rad_s)`` or
    ``(t_s, gyro_rad_s, accel_g)``, or None where it feeds none (nothing is written then); recorded
    right after the points, so that a reader finds them with the frame they precede."""
    t_end = ns(frame.t_end_s)
    writer.write_points(t_end, frame_id, frame.xyz, frame.t_ns, frame.reflectivity)
    if imu is not None:
        writer.write_imu(t_end, frame_id, *imu)
    write_record(writer, DetectionRecord.from_output(t_end, frame_id, out))
    write_record(writer, HeadEstimateRecord.from_output(t_end, frame_id, out))
    if getattr(out, "sky", None) is not None:      # the multi-object tracker: every track
        write_record(writer, TracksRecord.from_output(t_end, frame_id, out))
    return t_end


PARSERS = {DETECTIONS: DetectionRecord.from_json, HEAD: HeadEstimateRecord.from_json,
           COMMANDS: CommandRecord.from_json, TRUTH: TruthRecord.from_json,
           TRUTH_OBJECTS: ObjectTruthRecord.from_json, TRACKS: TracksRecord.from_json}


def parse(channel: str, record: dict):
    """The typed record of a JSON record read from ``channel`` (the dict itself on other channels);
    :class:`RecordError` naming the field for one whose fields are missing or not of their type."""
    p = PARSERS.get(channel)
    if p is None:
        return record
    _field(record, "t_ns")
    return p(record)
