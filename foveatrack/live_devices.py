"""The live devices of a daemon config: the head on a serial port, the Livox lidar on UDP.

Every live driver (the daemon, the live speed-table calibration) opens, reads and writes them through
this module, so what a bench sees -- the messages for a wrong port or address, the clock mapping,
the silence watchdog, the command encoding -- is one piece:

* :func:`open_devices` opens the head first, then the lidar (a port that cannot be used fails the
  start before anything else exists) and names the config key that was wrong.
* :class:`LidarStream` polls the lidar client and keeps what a driver needs from the packets: when
  the last one arrived (the watchdog) and the host - sensor clock offset.
* :class:`HeadLink` writes :class:`~foveatrack.control.HeadCommand` s as Pelco frames (each distinct
  command encoded once).

Clock offset: the host time of a sensor time is ``t_sensor + offset`` with ``offset = min over
packets (host receive time - time of the packet's last point)``: the offset at the first packet,
lowered whenever a packet arrives sooner than it predicts.  The mapping is exact up to the smallest
transit delay seen (on loopback well under 1 ms; on Ethernet ~0.1 ms) and drifts with the sensor's
clock error (0.1 ms per 100 s at 1 ppm).
"""

from __future__ import annotations

import errno
import json
import math
import time
from dataclasses import asdict, dataclass, is_dataclass
from pathlib import Path

from foveatrack.control import HeadCommand
from foveatrack.errors import UserError
from foveatrack.first_failure import StopsAtFirstFailure, close_quietly
from foveatrack.mcap_names import JOURNAL_SUFFIX, journal_path  # noqa: F401 (its callers import them here)


def counters_text(counters: dict) -> str:
    """A lidar client's or stream's counters in words for an error message (``cmd_sent 20,
    cmd_timeouts 19, ...``): what tells a lidar that never answered from one whose packets were
    dropped (the calibrations printed the raw dict)."""
    return ", ".join(f"{k} {v}" for k, v in counters.items()) or "none"


def open_head(config):
    """The head's :class:`gimbal.client.HeadClient`, open now, or a UserError naming ``[head] port``
    (or the option that replaced it, :meth:`~foveatrack.device_config.DaemonConfig.named_head_port`).

    The device is identified once (:mod:`foveatrack.serial_identity`; a ``/dev/serial/by-id/`` name of
    it is opened instead of ``/dev/ttyUSB0`` where there is one) and every reopen after a disconnect
    must find the same device: the client refuses to write to another (``open_refusals``)."""
    from foveatrack.serial_identity import ReopenGuard, identify
    from gimbal.client import HeadClient
    from gimbal.errors import GimbalError

    h = config.head
    ident = identify(h.port)
    open_path = ident.by_id if ident is not None and ident.by_id else h.port
    if open_path != h.port:
        ident = identify(open_path)
    guard = None if ident is None else ReopenGuard(ident, open_path)
    try:
        head = HeadClient(open_path, baud=h.baud, address=h.address, protocol=h.protocol, open_guard=guard)
    except GimbalError as exc:
        raise UserError(f"{config.path} [head]: {exc}") from None
    if not head.connected and head.stats.open_locked:
        raise UserError(f"{config.named_head_port()} is in use by another process (it holds the port's "
                        "exclusive lock): another daemon or program drives this head; stop it first, or give "
                        "this one its own head")
    if not head.connected and head.last_open_errno in (errno.EACCES, errno.EPERM):
        # the port is there, but not this user's: "start a server first" would send them the wrong way
        raise UserError(_access_denied_text(config, open_path, head.last_open_errno, head.last_open_error))
    if not head.connected:
        # A port that is wrong at start (a typo, an adapter not plugged in, a regular file, a server not
        # started) would otherwise leave the driver commanding no head, silently: the link reconnects by
        # itself only once it has been up.
        raise UserError(f"{config.named_head_port()} cannot be opened ({head.last_open_error}); "
                        "give the head's serial device (/dev/ttyUSB0) or a pyserial URL (socket://host:port, "
                        "rfc2217://host:port) that exists now, e.g. start 'foveatrack gimbal serve --link PATH' first")
    head.identity, head.open_path = ident, open_path
    return head


def _access_denied_text(config, open_path: str, err: int, error: str) -> str:
    """The message for a head port the system refused this user (EACCES, EPERM), blamed on where the
    port was given (:meth:`~foveatrack.device_config.DaemonConfig.named_head_port`: a ``--serial`` port
    is not the config file's).  A device path gets who may open it and how to become one of them
    (:func:`_port_access_advice`); a pyserial URL (``socket://``, ``rfc2217://``) is no device node, so
    the group and udev advice would be wrong for it: its own error is all there is to say."""
    import os

    reason = os.strerror(err)
    if "://" in open_path:
        return f"{config.named_head_port()} was refused ({error}); check that this user may connect to it"
    # pyserial's text repeats the errno and the path ("[Errno 13] could not open port P: [Errno 13]
    # Permission denied: 'P'"): the reason in words is enough beside the port's name
    return (f"{config.named_head_port()} exists but this user may not open it ({reason}); "
            f"{_port_access_advice(open_path)}")


def _port_access_advice(path: str) -> str:
    """What to do about a serial device this user may not open: join the group that may (a USB
    adapter's /dev/ttyUSB0 is ``root:dialout``, mode 660), or give the device a udev rule.  Who may
    open it is said by :func:`foveatrack.errors.access_text`, as for every file this user may not use."""
    import getpass
    import os
    import stat

    from foveatrack.errors import access_text, owner_names

    user = getpass.getuser()
    try:
        st = os.stat(path)
    except OSError:
        st = None
    who = access_text(path)
    if st is None or not who:
        return (f"add {user} to the serial devices' group (sudo usermod -aG dialout {user}, then log in again) "
                "or give the device a udev rule (GROUP=\"dialout\", MODE=\"0660\")")

    owner, group = owner_names(st)
    node = f"{os.path.realpath(path)} is {who}"
    if st.st_gid != 0 and st.st_mode & stat.S_IRGRP and st.st_mode & stat.S_IWGRP:
        return (f"{node}: add {user} to group {group} (sudo usermod -aG {group} {user}, then log in again), "
                "or give the device a udev rule")
    return (f"{node}, which only {owner} may open: give the device a udev rule that hands it to a group "
            f"{user} is in (e.g. /etc/udev/rules.d/99-pelco-head.rules: SUBSYSTEM==\"tty\", "
            f"ATTRS{{idVendor}}==\"VVVV\", ATTRS{{idProduct}}==\"PPPP\", GROUP=\"dialout\", MODE=\"0660\"; then "
            f"sudo usermod -aG dialout {user} and log in again)")


def open_lidar(config):
    """The lidar's :class:`foveatrack.livox.client.LivoxClient` (no-return points kept: they carry time)."""
    from foveatrack.livox.client import LivoxClient

    L = config.lidar
    return LivoxClient(L.sensor_ip, L.host_ip, cmd_port=L.cmd_port, data_port=L.data_port,
                       broadcast_port=L.broadcast_port, sensor_cmd_port=L.sensor_cmd_port,
                       point_rate_hz=L.point_rate_hz, broadcast_code=L.broadcast_code, keep_no_return=True)


def open_devices(config) -> tuple["HeadLink", object]:
    """``(HeadLink, LivoxClient)`` of ``config``: the head first, then the lidar; on a failure nothing
    is left open."""
    head = open_head(config)
    try:
        lidar = open_lidar(config)
    except BaseException:
        head.close()
        raise
    return HeadLink(head, config.head.address, config.head.protocol), lidar


class CommandJournal(StopsAtFirstFailure):
    """Every frame meant for the head, appended (one JSON line, flushed to the kernel) *before* it is
    written to the port: whatever a driver killed with SIGKILL got to the head is in it (the
    recording, written behind a queue, lost the frame in flight); ``foveatrack recover`` puts what
    the recording lacks back from it (:mod:`foveatrack.daemon.recover`).

    A line: ``t_mono_s`` (host monotonic time), ``t_unix_s`` (host UTC, for the recording's log
    time), ``raw_hex``, ``source`` (the daemon's: tracker, watchdog, ...; "" for a STOP outside the
    dead reckoning, "homing"), and ``send_t_s`` (the sensor time the dead reckoning gave it) where
    there is one.  The file is held under an exclusive ``flock`` while open: recovery never touches
    the journal (and so the recording) of a driver still running; the kernel drops the lock of a
    killed one."""

    def __init__(self, path):
        import fcntl

        import errno
        import os

        self.path = str(path)
        try:
            # never through a link (one planted beside a recording's name would append to any file the
            # daemon can write); the owner's alone, as the recording is
            fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0), 0o600)
        except OSError as exc:
            why = "it is a symbolic link" if exc.errno == errno.ELOOP else exc.strerror
            raise UserError(f"command journal {self.path}: cannot write ({why})") from None
        self._f = os.fdopen(fd, "a", buffering=1)
        try:
            fcntl.flock(self._f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            pass      # another holder (never expected: one journal per new recording); journaling goes on

    def write(self, raw: bytes, source: str = "", send_t_s: float | None = None) -> None:
        """Journal one frame.  Never raises: a journal that cannot be written (its disk full) must not
        keep the frame -- a STOP among them -- from the head; the first failure is kept in
        :attr:`error` (the driver says it) and nothing more is journaled (the file stays open: its
        lock still tells ``recover`` that a driver runs)."""
        t = "" if send_t_s is None or not math.isfinite(send_t_s) else f', "send_t_s": {send_t_s!r}'
        self._guarded(self._f.write, f'{{"t_mono_s": {time.monotonic():.6f}, "t_unix_s": {time.time():.6f}, '
                                     f'"raw_hex": "{raw.hex()}", "source": "{source}"{t}}}\n')

    def close(self) -> None:
        close_quietly(self._f)


def journal_in_use(path) -> bool:
    """Whether a running driver holds the journal at ``path`` (its :class:`CommandJournal` lock): the
    probe a recording's lock is asked with (:func:`foveatrack.file_lock.recording_in_use`)."""
    from foveatrack.file_lock import recording_in_use

    return recording_in_use(path)


@dataclass(frozen=True)
class JournalLine:
    """One line of a command journal (:class:`CommandJournal`); ``line_no`` counts from 1."""
    line_no: int
    t_mono_s: float
    raw: bytes
    source: str
    t_unix_s: float | None = None
    send_t_s: float | None = None


def read_journal(path) -> tuple[list[JournalLine], list[str]]:
    """The journal's lines, and one sentence per line that could not be read (skipped): a line cut
    short by a kill, or damaged.  Never raises for the contents; a missing file is an empty journal."""
    lines: list[JournalLine] = []
    bad: list[str] = []
    try:
        text = Path(path).read_bytes().decode("utf-8", errors="replace")
    except FileNotFoundError:
        return lines, bad
    for i, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        try:
            r = json.loads(line)
            if not isinstance(r, dict):
                raise ValueError("not a JSON object")
            t = r["t_mono_s"]
            if isinstance(t, bool) or not isinstance(t, (int, float)) or not math.isfinite(t):
                raise ValueError(f"t_mono_s {t!r} is not a time")
            raw = bytes.fromhex(r["raw_hex"])
            if not raw:
                raise ValueError("raw_hex is empty")
            src = r.get("source", "")
            if not isinstance(src, str):
                raise ValueError(f"source {src!r} is not a name")
            extra = {}
            for k in ("t_unix_s", "send_t_s"):
                v = r.get(k)
                if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v):
                    extra[k] = float(v)
            lines.append(JournalLine(i, float(t), raw, src, **extra))
        except KeyError as exc:
            bad.append(f"{path} line {i}: no field {exc} ({line[:60]!r}); skipped")
        except (ValueError, TypeError) as exc:
            bad.append(f"{path} line {i}: {exc} ({line[:60]!r}); skipped")
    return lines, bad


class HeadLink:
    """Pelco frames of :class:`HeadCommand` s to a :class:`gimbal.client.HeadClient` (reconnecting).

    journal : optional :class:`CommandJournal`: every frame is journaled before its write."""

    def __init__(self, client, address: int, protocol: str, journal: CommandJournal | None = None):
        self.client, self.address, self.protocol = client, address, protocol
        self.journal = journal
        self._encoded: dict[tuple, bytes] = {}   # a run uses a few dozen distinct commands

    @property
    def identity(self):
        """The device the head was found on at start (:class:`~foveatrack.serial_identity.SerialIdentity`;
        None for a URL)."""
        return getattr(self.client, "identity", None)

    @property
    def refused(self) -> str | None:
        """Why the last reopen was refused (another device holds the path), or None."""
        c = self.client
        if c.connected or not getattr(c.stats, "open_refusals", 0):
            return None
        return c.last_open_error

    def send_raw(self, raw: bytes, source: str = "", send_t_s: float | None = None) -> bool:
        """Write one prepared frame (journaled first, with the sensor time ``send_t_s`` the dead
        reckoning gave it where there is one); whether the link took it."""
        if self.journal is not None:
            self.journal.write(raw, source, send_t_s)
        return bool(self.client.send_frame(raw))

    def encode(self, cmd: HeadCommand) -> bytes:
        from gimbal.pelco import encode_pan_tilt

        key = (cmd.pan_dir, cmd.pan_byte, cmd.tilt_dir, cmd.tilt_byte)
        raw = self._encoded.get(key)
        if raw is None:
            raw = self._encoded[key] = encode_pan_tilt(self.address, *key, self.protocol)
        return raw

    def send(self, cmd: HeadCommand, source: str = "", send_t_s: float | None = None) -> tuple[bytes, bool]:
        """Write ``cmd``; returns the bytes and whether the link took them."""
        raw = self.encode(cmd)
        return raw, self.send_raw(raw, source, send_t_s)

    def stop(self) -> None:
        from foveatrack.control import STOP

        self.send(STOP)

    @property
    def connected(self) -> bool:
        return self.client.connected

    @property
    def stats(self):
        return self.client.stats

    def stats_dict(self) -> dict:
        s = getattr(self.client, "stats", None)
        return asdict(s) if is_dataclass(s) else {}

    def close(self) -> None:
        self.client.close()
        if self.journal is not None:
            self.journal.close()


class LidarStream:
    """The lidar's batches with what a driver keeps from them (see the module docstring): the host
    time of the last packet (``last_packet_mono``, for the watchdog) and the clock ``offset_s``.

    Point times pass the :class:`~foveatrack.sensor_time.SensorTimeGuard` first: a packet with a wrong
    time is dropped and counted, a sensor clock that restarted or jumped is re-anchored (``epoch`` + 1,
    the offset measured afresh; the driver restarts its frame slicer and its dead reckoning's clock),
    so neither a restarted lidar nor one bad packet stops a driver.  The batches returned are
    :class:`~foveatrack.sensor_time.Accepted` (``xyz``, ``t_ns``, ``reflectivity``, ``epoch``).
    """

    def __init__(self, client, guard=None):
        from foveatrack.sensor_time import SensorTimeGuard

        self.client = client
        self.guard = guard or SensorTimeGuard()
        self.offset_s: float | None = None
        self.last_packet_mono: float | None = None
        self._packets = 0

    @property
    def epoch(self) -> int:
        return self.guard.epoch

    @property
    def counters(self) -> dict:
        """The clock guard's counters (``clock_jumps``, ``lost_slots``, ``late_points``,
        ``duplicate_points``, ``stale_points``, ``early_points``, ``bad_time_points``, each kind also
        as ``*_segments``: :mod:`foveatrack.sensor_time`) and ``accepted_points``."""
        return {**self.guard.counters, "accepted_points": self.guard.accepted_points}

    def poll(self, timeout_s: float) -> tuple[float, list]:
        """``(host monotonic time, [Accepted, ...])`` of what arrived within ``timeout_s``."""
        batches = self.client.poll(timeout_s)
        now = time.monotonic()
        packets = self.client.counters.get("packets", 0)
        if packets != self._packets and self.last_packet_mono is None:
            self.last_packet_mono = now    # the first packet, even with wrong times: the lidar is there
        self._packets = packets
        out = []
        # the slot rate is the unit's (the client learns its model at the handshake)
        rate = getattr(getattr(self.client, "decoder", None), "point_rate_hz", None)
        self.guard.slot_ns = 1e9 / rate if rate else None
        accepted = self.guard.accepted_points
        for b in batches:
            if len(b):
                out.extend(self.guard.push(b.xyz, b.t_ns, b.reflectivity, now))
        if self.guard.accepted_points != accepted:
            # only points with believable times feed the watchdog and the clock offset (the guard's:
            # its newest accepted point, of the current clock; a new clock is measured afresh)
            self.last_packet_mono = now
            self.offset_s = self.guard.offset_s
        return now, out

    def take_jumps(self) -> list:
        """The re-anchors since the last call (:class:`~foveatrack.sensor_time.ClockJump`)."""
        return self.guard.take_jumps()

    def sensor_now_s(self, mono: float | None = None) -> float | None:
        """The sensor time of host time ``mono`` (default: now); None before the first packet."""
        if self.offset_s is None:
            return None
        return (time.monotonic() if mono is None else mono) - self.offset_s

    def silent_s(self, now: float) -> float | None:
        """Seconds since the last packet (None: none yet)."""
        return None if self.last_packet_mono is None else now - self.last_packet_mono
