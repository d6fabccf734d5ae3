"""The device configuration: the daemon's TOML file, validated on load (every error names the file,
the key and what is allowed).  It names the lidar, the head and their limits, so the daemon and the
live calibrations (speed table, IMU) read it from here, below all three (issue 25: the calibration
imported it from the daemon package).  Example: ``examples/daemon-virtual.toml``; reference: ``docs/daemon.md``.

Tables::

    [lidar]      sensor_ip, host_ip (both required), cmd_port, data_port, broadcast_port (each its own; 0 = any; false = no
                 discovery, then sensor_cmd_port), sensor_cmd_port, point_rate_hz, broadcast_code
    [head]       port (device path or pyserial URL), baud (a standard rate, gimbal.client.STANDARD_BAUDS,
                 as a scene's [gimbal] baud), address, protocol ("D" | "P"),
                 speed_table ("nominal" | path to a calibrated table JSON, relative to this file),
                 pan_speed_max_deg_s, tilt_speed_max_deg_s, pan_turbo_deg_s (the nominal table),
                 max_pan_byte, max_tilt_byte, allow_turbo, tilt_limits_deg, tilt_margin_deg,
                 pan0_deg, tilt0_deg (the pose at start, e.g. after homing),
                 on_start ("assume" | "home": drive to home_pan_deg/home_tilt_deg first),
                 on_reconnect ("stop" | "home" | "keep"), home_pan_deg, home_tilt_deg, home_wait_s
    [tracker]    foveatrack.tracker.TrackerConfig keys (rate_hz is the loop rate)
    [recording]  path ("{time}" becomes the UTC start time; its directory must exist unless
                 make_dirs = true), flush_every_frames, compression, points_dtype, queue_frames, overwrite,
                 segment_minutes (default 60: a new file every hour, each complete, so memory stays bounded
                 on long runs; 0: one file), writeback_mb (default 32: the file's pages sent to the disk
                 and dropped from the page cache every 32 MB; 0: left to the kernel)
    [daemon]     watchdog_s, max_frame_backlog, stale_frame_s, batch_queue, status_period_s, log,
                 control_socket (the operator's socket of a [tracker.sky] daemon: foveatrack daemon pin)
    [pose_check] the head's pose checked against the background (foveatrack.pose_check.PoseCheckConfig:
                 enabled, bound_deg, ...; off unless enabled = true)
"""

from __future__ import annotations

import datetime as _dt
import ipaddress
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Mapping

from foveatrack.config_util import as_bool, as_choice, as_float, as_path_text, as_table, as_vec, check_keys, read_toml
from foveatrack.errors import UserError
from foveatrack.pose_check import PoseCheckConfig
from foveatrack.speed_table import SpeedTable
from foveatrack.tracker import TrackerConfig
from foveatrack.gate import Limits
from gimbal.head_facts import DEFAULT_HEAD, HeadFacts


@dataclass(frozen=True)
class LidarConfig:
    # the addresses are required (a site's, never a default: 192.168.1.50/.5 once stood in silently);
    # the ports default to the Livox SDK's own (protocol facts, docs/daemon.md)
    sensor_ip: str
    host_ip: str
    cmd_port: int = 56001
    data_port: int = 56000
    broadcast_port: int | None = 55000
    sensor_cmd_port: int | None = None
    point_rate_hz: float | None = None
    broadcast_code: str | None = None


@dataclass(frozen=True)
class HeadConfig:
    port: str                           # required: a missing port once became /dev/ttyUSB0 silently
    baud: int = DEFAULT_HEAD.baud
    address: int = 1
    protocol: str = DEFAULT_HEAD.protocol
    speed_table: str = "nominal"
    pan_speed_max_deg_s: float = 15.0
    tilt_speed_max_deg_s: float = 2.0
    pan_turbo_deg_s: float = 20.0
    # the head's facts and limits: defaults from gimbal.head_facts.DEFAULT_HEAD, declared there once
    max_pan_byte: int = DEFAULT_HEAD.max_pan_byte
    max_tilt_byte: int = DEFAULT_HEAD.max_tilt_byte
    allow_turbo: bool = DEFAULT_HEAD.allow_turbo
    tilt_limits_deg: tuple[float, float] = DEFAULT_HEAD.tilt_limits_deg
    tilt_margin_deg: float = DEFAULT_HEAD.tilt_margin_deg   # the gate's, inside the tracker's 3 deg
    pan0_deg: float = DEFAULT_HEAD.pan0_deg
    tilt0_deg: float = DEFAULT_HEAD.tilt0_deg
    on_start: str = "assume"            # the pose at start: ON_START
    on_reconnect: str = "stop"          # what a reconnected head's unknown pose gets: ON_RECONNECT
    home_pan_deg: float | None = None   # where "home" drives the head (default pan0_deg, tilt0_deg)
    home_tilt_deg: float | None = None
    home_wait_s: float | None = None    # how long the absolute move may take (default: the worst case)

    @property
    def home_deg(self) -> tuple[float, float]:
        return (self.pan0_deg if self.home_pan_deg is None else self.home_pan_deg,
                self.tilt0_deg if self.home_tilt_deg is None else self.home_tilt_deg)

    @property
    def facts(self) -> HeadFacts:
        """The head's facts (stops, start pose, protocol, baud, limits) the tracker and the gate read;
        the daemon measures each send, so no fixed send delay."""
        return HeadFacts(self.tilt_limits_deg, self.pan0_deg, self.tilt0_deg, self.protocol, self.baud, None,
                         self.max_pan_byte, self.max_tilt_byte, self.allow_turbo, self.tilt_margin_deg)

    @property
    def limits(self) -> Limits:
        """The command gate's limits for this head (:mod:`foveatrack.gate`)."""
        return Limits.of(self.facts)

    @property
    def frame_time_s(self) -> float:
        """One command frame of this head's protocol on the wire at its baud [s] (Pelco-D 7 bytes,
        Pelco-P 8: :func:`gimbal.pelco.frame_time_s`)."""
        return self.facts.frame_time_s


@dataclass(frozen=True)
class RecordingConfig:
    path: str | None = None
    flush_every_frames: int = 1
    compression: str = "lz4"
    points_dtype: str = "float64"
    queue_frames: int = 50
    overwrite: bool = False
    make_dirs: bool = False     # create a missing directory (else it must exist: a typo made a new tree)
    segment_minutes: float | None = 60.0   # a new file every this many minutes, None: one (foveatrack.recording.segments)
    writeback_mb: float = 32.0  # the file's pages to the disk and out of the cache every this many MB, 0: the kernel's (foveatrack.recording.writeback)


@dataclass(frozen=True)
class LoopConfig:
    watchdog_s: float = 0.5
    max_frame_backlog: int = 3
    stale_frame_s: float = 0.2
    batch_queue: int = 2000
    status_period_s: float = 0.5
    log: str | None = None
    control_socket: str | None = None   # the operator's socket ([tracker.sky]; DaemonConfig.control_socket_path)


@dataclass(frozen=True)
class DaemonConfig:
    path: str
    text: str
    lidar: LidarConfig
    head: HeadConfig
    tracker_table: Mapping[str, Any]
    tracker: TrackerConfig
    recording: RecordingConfig
    loop: LoopConfig
    pose_check: PoseCheckConfig = PoseCheckConfig()
    head_port_option: str | None = None     # the command-line option that replaced [head] port ("--serial")

    def with_head_port(self, port: str, option: str) -> "DaemonConfig":
        """This config with the head's port given by ``option`` on the command line (``--serial``)."""
        return replace(self, head=replace(self.head, port=port), head_port_option=option)

    def named_head_port(self) -> str:
        """The head's port and where it was given, for the errors about it: ``--serial '/dev/ttyUSB1'``
        or ``daemon.toml [head]: port '/dev/ttyUSB0'`` (a port given on the command line and blamed on
        the file sent a user to fix a config that was right)."""
        if self.head_port_option is not None:
            return f"{self.head_port_option} {self.head.port!r}"
        return f"{self.path} [head]: port {self.head.port!r}"

    @property
    def tracker_overrides(self) -> dict:
        """What the head's facts set on top of ``[tracker]`` (:meth:`TrackerConfig.with_head`), kept for replay."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in self.head.facts.tracker_values().items()}

    def warnings(self) -> list[str]:
        """What in this config runs but gives wrong results, in words (printed at start, logged, and
        kept in the status line)."""
        out = []
        if self.head.speed_table == "nominal":
            out.append(f"{self.path} [head] speed_table = \"nominal\": the head is uncalibrated; the dead reckoning "
                       "uses the datasheet's speeds, not this unit's, and the world it reconstructs drifts (seen: "
                       "the daemon believed pan -58 to -78 deg while the head was at -31 to -44 deg after 20 s); "
                       "measure the table first: foveatrack calibrate --config THIS.toml --corner X Y Z --out "
                       "table.json, then speed_table = \"table.json\"")
        else:
            # a table a user supplies: speeds that fall as the byte rises, bytes it has no speed for (up
            # to the bytes this config may send: calibrate --config measures none above them)
            limits = {"pan": self.head.max_pan_byte, "tilt": self.head.max_tilt_byte}
            out += [f"{self.path} [head] speed_table {self.head.speed_table!r}: {p}"
                    for p in self.speed_table().problems(max_byte=limits)]
        if self.sky and isinstance(self.tracker_table["sky"], dict) and \
                "field_half_angle_deg" not in self.tracker_table["sky"]:
            out.append(f"{self.path} [tracker.sky] has no field_half_angle_deg: every track counts as in the lidar's "
                       "view, so one the head has turned away from is deleted after lost_after_s (2 s) unseen instead "
                       "of lost_out_of_view_s (5 s), before a revisit can reach it; set it to your lidar's field "
                       "(a Mid-40's: 19.2)")
        return out

    def speed_table(self) -> SpeedTable:
        h = self.head
        if h.speed_table == "nominal":
            return SpeedTable.nominal(h.pan_speed_max_deg_s, h.tilt_speed_max_deg_s, h.pan_turbo_deg_s)
        p = Path(h.speed_table)
        if not p.is_absolute():
            p = Path(self.path).parent / p
        return SpeedTable.load(p)

    def recording_path(self, now: _dt.datetime | None = None) -> Path | None:
        """The recording's file, absolute and resolved (a path relative to the config file gave
        ``examples/../out/runs/...`` in messages and logs, which a user had to work out)."""
        if self.recording.path is None:
            return None
        now = now or _dt.datetime.now(_dt.timezone.utc)
        p = Path(self.recording.path.replace("{time}", now.strftime("%Y%m%dT%H%M%SZ")))
        return (p if p.is_absolute() else Path(self.path).parent / p).resolve()

    @property
    def sky(self) -> bool:
        """The config asks for the multi-object tracker (a ``[tracker.sky]`` table)."""
        return "sky" in self.tracker_table

    def control_socket_path(self) -> Path:
        """The operator's socket (``foveatrack daemon pin``), absolute: ``[daemon] control_socket``
        (relative to this file), by default ``STEM.control.sock`` (this file's stem) in the
        recording's directory, or beside this file when there is no recording or its directory
        changes with the start time (``{time}``)."""
        if self.loop.control_socket is not None:
            p = Path(self.loop.control_socket)
        else:
            name = Path(self.path).stem + ".control.sock"
            rec = self.recording.path
            p = Path(rec).parent / name if rec is not None and "{time}" not in str(Path(rec).parent) else Path(name)
        return (p if p.is_absolute() else Path(self.path).parent / p).resolve()

    def control_socket_dir_made(self) -> bool:
        """Whether the daemon creates the control socket's missing directory: it is the recording's,
        which ``[recording] make_dirs`` lets it create."""
        rec = self.recording_path()
        return (self.recording.make_dirs and rec is not None
                and self.control_socket_path().parent == rec.parent.resolve())

    def check_control_socket(self) -> None:
        """A UserError naming ``[daemon] control_socket`` when the multi-object tracker's control socket
        could not be made at its path: an existing file that is not a socket, or a missing directory
        the daemon does not create (:meth:`control_socket_dir_made`).  ``daemon --check`` asks it,
        as the start does (``--check`` passed both, and the run then failed)."""
        import os
        import stat

        if not self.sky:
            return
        path = self.control_socket_path()
        key = f"{self.path} [daemon] control_socket"
        if (path.exists() or path.is_symlink()) and not stat.S_ISSOCK(os.lstat(path).st_mode):
            raise UserError(f"{key}: {path} exists and is not a socket; remove it or set control_socket to "
                            "another path")
        if not path.parent.is_dir():
            if self.control_socket_dir_made():
                return
            raise UserError(f"{key}: the directory {path.parent} does not exist; create it or set "
                            "control_socket to a path in an existing directory")
        if not os.access(path.parent, os.W_OK | os.X_OK):
            raise UserError(f"{key}: {path.parent} is not a directory this user can write in")

    def recording_exists_message(self, path) -> str:
        """What to say of a recording ``path`` that exists (the start and ``--check`` say the same)."""
        why = ("two starts within the same second gave the same '{time}' name; start again a second later"
               if "{time}" in str(self.recording.path) else
               "put '{time}' in it for a new file per start (e.g. path = \"runs/{time}.mcap\")")
        return (f"{self.path} [recording] path: {path} already exists and is never overwritten unless asked; "
                f"{why}, or set overwrite = true in [recording] to replace it")

    def check_recording_dir(self) -> None:
        """A UserError naming ``[recording] path`` when the recording could not be written there: its
        directory missing (and ``make_dirs`` off) or not writable.  The daemon's start and
        ``daemon --check`` ask the same question here (``--check`` used to pass such a config, and
        the run then failed at once)."""
        import os

        path = self.recording_path()
        if path is None:
            return
        # what the writer refuses at the start, refused here too (--check passed both)
        if path.is_dir():
            raise UserError(f"{self.path} [recording] path: {path} is a directory; name the recording's file "
                            "(e.g. .../daemon-{time}.mcap)")
        if path.exists() and not self.recording.overwrite:
            raise UserError(self.recording_exists_message(path))
        parent = path.parent
        if not parent.is_dir() and not self.recording.make_dirs:
            raise UserError(f"{self.path} [recording] path: the directory {parent} does not exist; create it "
                            "(a mistyped path would otherwise start a new tree) or set make_dirs = true in [recording]")
        existing = next((d for d in (parent, *parent.parents) if d.exists()), None)
        if existing is not None and (not existing.is_dir() or not os.access(existing, os.W_OK | os.X_OK)):
            raise UserError(f"{self.path} [recording] path: {existing} is not a directory this user can write in")


# What the daemon does when the head's link comes back after a disconnect.  The head reports no
# pose, and one that lost power comes back at its power-on pose, so the dead reckoning is void:
#   "stop": STOP, report "pose unknown" and send no tracker command until the daemon is restarted
#           (after the head was homed by hand)
#   "home": STOP, then the absolute move (Pelco 0x4B/0x4D) to home_pan_deg/home_tilt_deg, wait
#           home_wait_s for it, and track on from there
#   "keep": trust the dead reckoning (only a link that was cut while the head kept its power)
ON_RECONNECT = ("stop", "home", "keep")
# The head reports no pose: at start it is assumed at pan0_deg/tilt0_deg (where a previous run, or a
# hand, may not have left it: a second run tracked from 0/0 with the head at -61 deg, 1 frame of 374
# detected), or driven home first by absolute moves ("home", as on_reconnect = "home" does)
ON_START = ("assume", "home")


def _int(v, key, where, lo, hi):
    if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
        raise UserError(f"{where}: {key} must be an integer in [{lo}, {hi}], got {v!r}")
    return v


def _ip(v, key, where):
    try:
        return str(ipaddress.IPv4Address(v))
    except (ValueError, TypeError):
        raise UserError(f"{where}: {key} must be a dotted IPv4 address like 192.168.1.50, got {v!r}") from None


def _lidar(t: Mapping, w: str) -> LidarConfig:
    check_keys(t, ["sensor_ip", "host_ip", "cmd_port", "data_port", "broadcast_port", "sensor_cmd_port",
                   "point_rate_hz", "broadcast_code"], w)
    kw: dict = {}
    for k, what in (("sensor_ip", "the lidar's address"), ("host_ip", "this host's address on the lidar's network")):
        if k not in t:
            raise UserError(f"{w}: {k} is required ({what}, e.g. {k} = \"192.168.1.50\"); there is no default")
        kw[k] = _ip(t[k], k, w)
    for k in ("cmd_port", "data_port"):
        if k in t:
            kw[k] = _int(t[k], k, w, 0, 65535)
    if "broadcast_port" in t:
        v = t["broadcast_port"]
        kw["broadcast_port"] = None if v is False else _int(v, "broadcast_port", w, 0, 65535)
    if "sensor_cmd_port" in t:
        kw["sensor_cmd_port"] = _int(t["sensor_cmd_port"], "sensor_cmd_port", w, 1, 65535)
    if "point_rate_hz" in t:
        kw["point_rate_hz"] = as_float(t["point_rate_hz"], "point_rate_hz", w, lo=0, lo_open=True, hi=2e6)
    if "broadcast_code" in t:
        v = t["broadcast_code"]
        if not isinstance(v, str) or not 0 < len(v) <= 16:
            raise UserError(f"{w}: broadcast_code must be a string of 1-16 characters, got {v!r}")
        kw["broadcast_code"] = v
    cfg = LidarConfig(**kw)
    if cfg.broadcast_port is None and cfg.sensor_cmd_port is None:
        raise UserError(f"{w}: broadcast_port = false (no discovery) needs sensor_cmd_port (65000 on a Livox)")
    _distinct_ports(cfg, t, w)
    return cfg


def _distinct_ports(cfg: LidarConfig, t: Mapping, w: str) -> None:
    """The host's own ports are bound one socket each: a repeated one failed at start as 'Address
    already in use' blamed on another process.  0 (any free port) may repeat; false is no port."""
    seen: dict[int, str] = {}
    for k in ("cmd_port", "data_port", "broadcast_port"):
        v = getattr(cfg, k)
        if not v:
            continue
        if v in seen:
            keys = " and ".join(f"{key}{'' if key in t else ' (its default)'}" for key in (seen[v], k))
            raise UserError(f"{w}: {keys} are both {v}; each of cmd_port, data_port and broadcast_port "
                            "needs a port of its own (0 = any free port)")
        seen[v] = k


def _head(t: Mapping, w: str) -> HeadConfig:
    check_keys(t, [f for f in HeadConfig.__dataclass_fields__], w)
    kw: dict = {}
    if "port" not in t:
        raise UserError(f"{w}: port is required (the head's serial device, best a /dev/serial/by-id/ name, or a "
                        "pyserial URL such as socket://host:port); there is no default")
    kw["port"] = as_path_text(t["port"], "port", w, "a device path (/dev/ttyUSB0) or a pyserial URL (socket://host:port)")
    if "baud" in t:
        from gimbal.client import STANDARD_BAUDS   # the scene's rule too (sim/scene.py)

        v = t["baud"]
        if isinstance(v, bool) or not isinstance(v, int) or v not in STANDARD_BAUDS:
            raise UserError(f"{w}: baud must be a standard rate ({', '.join(map(str, STANDARD_BAUDS))}), got {v!r}")
        kw["baud"] = v
    if "address" in t:
        kw["address"] = _int(t["address"], "address", w, 1, 255)
    if "protocol" in t:
        kw["protocol"] = as_choice(t["protocol"], "protocol", w, ("D", "P"))
    if "speed_table" in t:
        kw["speed_table"] = as_path_text(t["speed_table"], "speed_table", w,
                                         "'nominal' or the path of a calibrated table JSON")
    for k in ("pan_speed_max_deg_s", "tilt_speed_max_deg_s", "pan_turbo_deg_s"):
        if k in t:
            kw[k] = as_float(t[k], k, w, lo=0, lo_open=True, hi=360)
    for k in ("max_pan_byte", "max_tilt_byte"):
        if k in t:
            kw[k] = _int(t[k], k, w, 0, 0x3F)
    if "allow_turbo" in t:
        kw["allow_turbo"] = as_bool(t["allow_turbo"], "allow_turbo", w)
    if "tilt_limits_deg" in t:
        lo, hi = as_vec(t["tilt_limits_deg"], "tilt_limits_deg", w, 2)
        if not -90 <= lo < hi <= 90:
            raise UserError(f"{w}: tilt_limits_deg must be [lo, hi] with -90 <= lo < hi <= 90, got {t['tilt_limits_deg']!r}")
        kw["tilt_limits_deg"] = (lo, hi)
    if "tilt_margin_deg" in t:
        kw["tilt_margin_deg"] = as_float(t["tilt_margin_deg"], "tilt_margin_deg", w, lo=0, hi=45)
    if "pan0_deg" in t:
        kw["pan0_deg"] = as_float(t["pan0_deg"], "pan0_deg", w, lo=-180, hi=180)
    if "tilt0_deg" in t:
        kw["tilt0_deg"] = as_float(t["tilt0_deg"], "tilt0_deg", w, lo=-90, hi=90)
    if "on_start" in t:
        kw["on_start"] = as_choice(t["on_start"], "on_start", w, ON_START)
    if "on_reconnect" in t:
        kw["on_reconnect"] = as_choice(t["on_reconnect"], "on_reconnect", w, ON_RECONNECT)
    if "home_pan_deg" in t:
        kw["home_pan_deg"] = as_float(t["home_pan_deg"], "home_pan_deg", w, lo=-180, hi=180)
    if "home_tilt_deg" in t:
        kw["home_tilt_deg"] = as_float(t["home_tilt_deg"], "home_tilt_deg", w, lo=-90, hi=90)
    if "home_wait_s" in t:
        kw["home_wait_s"] = as_float(t["home_wait_s"], "home_wait_s", w, lo=0, hi=600)
    cfg = HeadConfig(**kw)
    lo, hi = cfg.tilt_limits_deg
    if cfg.home_tilt_deg is not None and not lo <= cfg.home_tilt_deg <= hi:
        raise UserError(f"{w}: home_tilt_deg {cfg.home_tilt_deg} is outside tilt_limits_deg {list(cfg.tilt_limits_deg)}")
    if not lo <= cfg.tilt0_deg <= hi:
        raise UserError(f"{w}: tilt0_deg {cfg.tilt0_deg} is outside tilt_limits_deg {list(cfg.tilt_limits_deg)}")
    return cfg


def _recording(t: Mapping, w: str) -> RecordingConfig:
    check_keys(t, [f for f in RecordingConfig.__dataclass_fields__], w)
    kw: dict = {}
    if "path" in t:
        kw["path"] = as_path_text(t["path"], "path", w, "a file name (e.g. 'runs/{time}.mcap')")
    if "flush_every_frames" in t:
        kw["flush_every_frames"] = _int(t["flush_every_frames"], "flush_every_frames", w, 1, 1000)
    if "compression" in t:
        kw["compression"] = as_choice(t["compression"], "compression", w, ("lz4", "zstd", "none"))
    if "points_dtype" in t:
        kw["points_dtype"] = as_choice(t["points_dtype"], "points_dtype", w, ("float64", "float32"))
    if "queue_frames" in t:
        kw["queue_frames"] = _int(t["queue_frames"], "queue_frames", w, 1, 10_000)
    if "overwrite" in t:
        kw["overwrite"] = as_bool(t["overwrite"], "overwrite", w)
    if "make_dirs" in t:
        kw["make_dirs"] = as_bool(t["make_dirs"], "make_dirs", w)
    if "segment_minutes" in t:
        m = as_float(t["segment_minutes"], "segment_minutes", w, lo=0, hi=10_080)
        if 0 < m < 0.01:
            raise UserError(f"{w}: segment_minutes {m} is under 0.01 (0.6 s); 0 keeps one file for the run")
        kw["segment_minutes"] = m or None
    if "writeback_mb" in t:
        kw["writeback_mb"] = as_float(t["writeback_mb"], "writeback_mb", w, lo=0, hi=65_536)
    return RecordingConfig(**kw)


def _loop(t: Mapping, w: str) -> LoopConfig:
    check_keys(t, [f for f in LoopConfig.__dataclass_fields__], w)
    kw: dict = {}
    if "watchdog_s" in t:
        kw["watchdog_s"] = as_float(t["watchdog_s"], "watchdog_s", w, lo=0.05, hi=60)
    if "max_frame_backlog" in t:
        kw["max_frame_backlog"] = _int(t["max_frame_backlog"], "max_frame_backlog", w, 1, 100)
    if "stale_frame_s" in t:
        kw["stale_frame_s"] = as_float(t["stale_frame_s"], "stale_frame_s", w, lo=0.01, hi=10)
    if "batch_queue" in t:
        kw["batch_queue"] = _int(t["batch_queue"], "batch_queue", w, 10, 1_000_000)
    if "status_period_s" in t:
        kw["status_period_s"] = as_float(t["status_period_s"], "status_period_s", w, lo=0.05, hi=60)
    if "log" in t:
        kw["log"] = as_path_text(t["log"], "log", w, "a file name for JSON lines")
    if "control_socket" in t:
        kw["control_socket"] = as_path_text(t["control_socket"], "control_socket", w,
                                            "a file name for the operator's Unix socket")
    return LoopConfig(**kw)


def config_from_mapping(data: Mapping, where: str = "daemon config", text: str = "") -> DaemonConfig:
    check_keys(data, ["lidar", "head", "tracker", "recording", "daemon", "pose_check"], where)
    for k in ("lidar", "head"):
        if k not in data:
            raise UserError(f"{where}: missing [{k}] table (see examples/daemon-virtual.toml)")
    tables = {k: as_table(data.get(k, {}), k, where) for k in ("lidar", "head", "tracker", "recording", "daemon")}
    lidar = _lidar(tables["lidar"], f"{where} [lidar]")
    head = _head(tables["head"], f"{where} [head]")
    tt = dict(tables["tracker"])
    tracker = TrackerConfig.from_mapping(tt, where=f"{where} [tracker]")
    cfg = DaemonConfig(where, text, lidar, head, tt, tracker,
                       _recording(tables["recording"], f"{where} [recording]"),
                       _loop(tables["daemon"], f"{where} [daemon]"),
                       PoseCheckConfig.from_mapping(as_table(data.get("pose_check", {}), "pose_check", where),
                                                    f"{where} [pose_check]"))
    cfg = replace(cfg, tracker=tracker.with_head(head.facts, tt, f"{where} [tracker]"))
    if head.speed_table != "nominal":
        p = Path(head.speed_table)
        p = p if p.is_absolute() else Path(where).parent / p
        if not p.is_file():
            raise UserError(f"{where} [head]: speed_table {head.speed_table!r} is not a file "
                            f"(looked for {p}); use 'nominal' or a table from 'foveatrack calibrate'")
    return cfg


def load_config(path: str | Path) -> DaemonConfig:
    """Read and validate a daemon config file; UserError naming the file and key on any problem."""
    data, text = read_toml(path, "daemon config", "example: examples/daemon-virtual.toml")
    return config_from_mapping(data, str(path), text)
