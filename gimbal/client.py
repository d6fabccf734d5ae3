"""The tracker's side of the serial line: a Pelco head client over any pyserial URL or path.

``HeadClient`` opens ``/dev/ttyUSB0``, a pty path, ``socket://host:port``, ``rfc2217://...`` or
``spy://...`` alike (``serial.serial_for_url``); the protocol is kept apart from the port (the
codec is :mod:`gimbal.pelco`, the framing :mod:`gimbal.framing`).

Rules that keep the control loop alive (it runs at the lidar's 10 Hz frame rate):

* Every call returns within ``write_timeout_s`` per frame written plus ``read_timeout_s`` for a
  query; the defaults keep the worst case of :meth:`HeadClient.query_position` (two frames
  written, replies awaited) under one lidar frame, 100 ms.
* Failures never raise: they are counted in :attr:`HeadClient.stats` and reported by a ``False``
  / ``None`` return.  A port that disappears (unplugged adapter, server gone) is closed; the next
  call reopens it, at most once per ``reconnect_interval_s`` so a dead port costs little.
* Replies are only accepted from our address, in our envelope, as 0x59 / 0x5B frames, so an
  RS-485 echo of our own queries is ignored.  Position words outside 0-35999 are counted as bad
  replies.  A head with ``feedback='at-rest'`` sends in-range garbage while moving, which no
  client can detect; trust positions only when the head has been commanded to stop.

The client reads the wall clock for its timeouts; it is real-time code and lives outside ``sim``.
"""

from __future__ import annotations

import os
import select
import time
from dataclasses import dataclass

import serial

try:
    from termios import error as TermiosError   # tcdrain on a pty whose other side went away (EIO)
except ImportError:  # pragma: no cover - not POSIX
    class TermiosError(Exception):
        pass

from gimbal.errors import GimbalError
from gimbal.framing import PelcoParser
from gimbal.pelco import (
    FRAME_LEN,
    encode_pan_tilt,
    encode_query_pan,
    encode_query_tilt,
    encode_stop,
    word_is_angle,
    word_to_pan_deg,
    word_to_tilt_deg,
)

FRAME_BUDGET_S = 0.1  # one lidar frame

STANDARD_BAUDS: tuple[int, ...] = (1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200)
"""Line speeds a head's UART is set to [bit/s]: the standard rates (the PTS family's DIP switches
offer 1200-9600, 2400 common; the faster ones are for other Pelco heads and adapters).  One
definition for every config that names a baud (a scene's ``[gimbal]``, a daemon's ``[head]``), so
a rate one accepts the other does not refuse."""
_READ_SLICE_S = 0.005  # a blocking read waits at most this long; the deadline is checked between


@dataclass
class ClientStats:
    frames_sent: int = 0
    write_failures: int = 0  # port errors on write (the port is then closed)
    write_timeouts: int = 0
    read_failures: int = 0  # port errors on read (the port is then closed)
    query_timeouts: int = 0  # no (valid) reply before the read deadline
    bad_replies: int = 0  # checksum-valid replies whose word is not an angle
    open_failures: int = 0
    open_refusals: int = 0  # reopens the open_guard refused (another device now holds the path)
    open_locked: int = 0  # opens refused because another process holds the port's exclusive lock
    opens: int = 0
    disconnects: int = 0

    @property
    def reconnects(self) -> int:
        return max(0, self.opens - 1)


class HeadClient:
    """Pelco-D/P client for one head.

    url_or_path : str, anything ``serial.serial_for_url`` opens
    baud : int [bit/s]
    address : int, the head's logical (DIP-switch) address
    protocol : 'D' or 'P'
    write_timeout_s : float > 0 [s] per write
    read_timeout_s : float > 0 [s], how long a query waits for its replies
    reconnect_interval_s : float >= 0 [s], least time between attempts to reopen a lost port
    tilt_zero : 'zenith' (PTS family) or 'level', the head's tilt word convention
    open_now : try to open in the constructor (failure is counted, not raised)
    open_guard : optional callable() -> None or a reason: asked before every reopen after the first
                 open; a reason refuses it (counted in ``open_refusals``, kept in ``last_open_error``),
                 so a client never writes to a device that is no longer its head
    """

    def __init__(
        self,
        url_or_path: str,
        baud: int = 9600,
        address: int = 1,
        protocol: str = "D",
        write_timeout_s: float = 0.02,
        read_timeout_s: float = 0.045,
        reconnect_interval_s: float = 0.5,
        tilt_zero: str = "zenith",
        open_now: bool = True,
        open_guard=None,
    ) -> None:
        if protocol not in FRAME_LEN:
            raise GimbalError(f"protocol={protocol!r} is not allowed; use 'D' or 'P'")
        if not write_timeout_s > 0 or not read_timeout_s > 0:
            raise GimbalError("write_timeout_s and read_timeout_s must be > 0")
        if 2 * write_timeout_s + read_timeout_s + _READ_SLICE_S > FRAME_BUDGET_S:
            raise GimbalError(
                f"2 x write_timeout_s + read_timeout_s = {2 * write_timeout_s + read_timeout_s} s "
                f"exceeds one lidar frame ({FRAME_BUDGET_S} s)"
            )
        encode_stop(address, protocol)  # validates the address for the envelope
        self.url = url_or_path
        self.baud = baud
        self.address = address
        self.protocol = protocol
        self.write_timeout_s = write_timeout_s
        self.read_timeout_s = read_timeout_s
        self.reconnect_interval_s = reconnect_interval_s
        self.tilt_zero = tilt_zero
        self.stats = ClientStats()
        self._ser = None
        self.last_open_error: str | None = None  # why the last attempt to open the port failed
        self.last_open_errno: int | None = None  # its errno, where the OS gave one (EACCES: not this user's)
        self._last_open_attempt = -float("inf")
        self._parser = PelcoParser(protocol)
        self.open_guard = open_guard
        if open_now:
            self._ensure_open(force=True)

    # -- port handling -----------------------------------------------------------------------
    @property
    def connected(self) -> bool:
        return self._ser is not None

    def _ensure_open(self, force: bool = False) -> bool:
        if self._ser is not None:
            return True
        now = time.monotonic()
        if not force and now - self._last_open_attempt < self.reconnect_interval_s:
            return False
        self._last_open_attempt = now
        if self.open_guard is not None and self.stats.opens:
            why = self.open_guard()
            if why:
                self.stats.open_refusals += 1
                self.last_open_error = why
                return False
        # A device path is locked (flock, pyserial's exclusive): a second process (another daemon with
        # the same [head] port) cannot open it and write a STOP into a head the first one drives.
        # URLs (socket://, rfc2217://) have no lock to take.
        lock = {} if "://" in self.url else {"exclusive": True}
        try:
            self._ser = serial.serial_for_url(
                self.url, baudrate=self.baud, timeout=_READ_SLICE_S,
                write_timeout=self.write_timeout_s, **lock,
            )
        except (serial.SerialException, OSError, ValueError) as exc:
            self.stats.open_failures += 1
            self.last_open_error = str(exc) or type(exc).__name__
            self.last_open_errno = getattr(exc, "errno", None)
            if lock and "exclusively lock" in self.last_open_error:
                self.stats.open_locked += 1
                self.last_open_error = (f"{self.url} is in use by another process, which holds its exclusive "
                                        f"lock ({self.last_open_error})")
            elif "Inappropriate ioctl" in self.last_open_error:
                # ENOTTY: an ordinary file (or any non-terminal) where a serial device was meant
                self.last_open_error = (f"{self.url} is not a serial device (a regular file or another "
                                        f"non-terminal: {self.last_open_error})")
            self._ser = None
            return False
        self.stats.opens += 1
        self.last_open_error = self.last_open_errno = None
        self._parser.reset()
        return True

    def _drop_port(self) -> None:
        self.stats.disconnects += 1
        try:
            self._ser.close()
        except Exception:  # noqa: BLE001 - the port is already broken; closing is best effort
            pass
        self._ser = None

    def close(self) -> None:
        if self._ser is not None:
            try:
                self._ser.close()
            finally:
                self._ser = None

    def __enter__(self) -> "HeadClient":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- writing -----------------------------------------------------------------------------
    def send_frame(self, frame: bytes) -> bool:
        """Write one frame; True if it went out whole."""
        if not self._ensure_open():
            return False
        try:
            n = self._write(frame)
            self._ser.flush()
        except serial.SerialTimeoutException:
            self.stats.write_timeouts += 1
            return False
        except (serial.SerialException, OSError, TermiosError):
            # (pyserial's flush is termios.tcdrain, whose error is no OSError: a head server killed
            # between the write and the drain raised it out of the daemon's loop)
            self.stats.write_failures += 1
            self._drop_port()
            return False
        if n is not None and n != len(frame):
            self.stats.write_timeouts += 1
            return False
        self.stats.frames_sent += 1
        return True

    def _write(self, frame: bytes) -> int:
        """Write ``frame`` within ``write_timeout_s``; the number of bytes the port took.

        On a POSIX port (a tty or pty path) the bytes go through ``os.write`` on pyserial's
        non-blocking descriptor, and a frame counts as written once the kernel took all of it, however
        late that was.  pyserial 3.5's own ``write`` checks its deadline *after* a complete write and
        raises ``SerialTimeoutException`` if it has passed (pyserial issue #281, open since 2017), so on
        a loaded machine (this process descheduled for 20 ms between two lines) a command that reached
        the head was reported lost:
        the daemon's dead reckoning then took the head for still running the previous command, and
        the live calibration aborted a leg.  Other ports (socket://, rfc2217://, ...) use pyserial's.
        """
        fd = getattr(self._ser, "fd", None)
        if not isinstance(fd, int) or not hasattr(self._ser, "pipe_abort_write_r"):   # not serialposix
            return self._ser.write(frame)
        view = memoryview(frame)
        deadline = time.monotonic() + self.write_timeout_s
        sent = 0
        while sent < len(frame):
            try:
                sent += os.write(fd, view[sent:])
            except (BlockingIOError, InterruptedError):
                pass
            if sent == len(frame):
                break
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([], [fd], [], left)[1]:
                raise serial.SerialTimeoutException(f"write timeout: {sent} of {len(frame)} bytes taken")
        return sent

    def send_speeds(self, pan_dir: int, pan_byte: int, tilt_dir: int, tilt_byte: int) -> bool:
        """Combined speed move (pan_dir +1 = LEFT, tilt_dir +1 = UP; bytes 0x00-0x3F, pan 0xFF
        = turbo).  Motion latches on the head until the next command."""
        frame = encode_pan_tilt(self.address, pan_dir, pan_byte, tilt_dir, tilt_byte,
                                self.protocol)
        return self.send_frame(frame)

    def stop(self) -> bool:
        return self.send_frame(encode_stop(self.address, self.protocol))

    # -- queries -----------------------------------------------------------------------------
    def query_position(self) -> tuple[float, float] | None:
        """Ask for pan and tilt (0x51, 0x53); ``(pan_deg, tilt_deg)`` or None.

        Returns within ~2 x write_timeout_s + read_timeout_s.  The head of the paper never
        answers (None, counted as a query timeout).
        """
        if not self._ensure_open():
            return None
        try:
            self._ser.reset_input_buffer()
        except (serial.SerialException, OSError):
            self.stats.read_failures += 1
            self._drop_port()
            return None
        self._parser.reset()
        if not self.send_frame(encode_query_pan(self.address, self.protocol)):
            return None
        if not self.send_frame(encode_query_tilt(self.address, self.protocol)):
            return None
        words = self._await_replies({"pan_reply", "tilt_reply"})
        if words is None:
            return None
        pan_w, tilt_w = words["pan_reply"], words["tilt_reply"]
        if not (word_is_angle(pan_w) and word_is_angle(tilt_w)):
            self.stats.bad_replies += 1
            return None
        return word_to_pan_deg(pan_w), word_to_tilt_deg(tilt_w, self.tilt_zero)

    def _await_replies(self, kinds: set[str]) -> dict[str, int] | None:
        deadline = time.monotonic() + self.read_timeout_s
        got: dict[str, int] = {}
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                self.stats.query_timeouts += 1
                return None
            try:
                data = self._ser.read(max(1, self._ser.in_waiting))
            except (serial.SerialException, OSError):
                self.stats.read_failures += 1
                self._drop_port()
                return None
            if not data:
                continue
            for cmd in self._parser.feed(data, time.monotonic()):
                if cmd.address == self.address and cmd.kind in kinds:
                    got[cmd.kind] = cmd.word
            if kinds <= got.keys():
                return got
