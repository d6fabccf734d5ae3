"""A virtual PTS-303H served on a pseudo-terminal, for real-time use (``foveatrack gimbal serve``).

Any Pelco-D/P controller that opens the printed device path with pyserial (or anything else that
opens a tty) drives the :class:`gimbal.pts303h.PTS303H` model behind it.  A pty has no baud
timing, so the server paces bytes itself (facts file, "pyserial for simulated devices"):

* a byte the controller writes is taken to arrive when it would have finished on a real line,
  10 bits / baud after the previous one (bytes written in one burst arrive one byte-time apart);
* reply bytes are written to the pty one at a time, each when its stop bit would end.

The server writes the head's true state as JSON lines (``t_s``, ``pan_deg``, ``tilt_deg``,
``pan_speed_deg_s``, ``tilt_speed_deg_s``; ``t_s`` counts from the server's start) every
``truth_period_s`` and once more when it stops.

It holds the pty's device side open itself, so controllers may close and reopen the path at will,
and puts it in raw mode (otherwise CR/LF translation would corrupt bytes such as 0x0D).

Time: this module never reads the wall clock; the caller passes ``clock`` (the CLI passes
``time.monotonic``), and the head model only ever sees virtual times derived from it.
"""

from __future__ import annotations

import contextlib
import json
import os
import select
import tty
from collections import deque
from collections.abc import Callable
from typing import TextIO

from gimbal.pelco import BITS_PER_BYTE  # 8N1: the link's facts live with the protocol
from gimbal.pts303h import PTS303H


class VirtualHeadServer:
    """Serve ``head`` on a new pty.

    head : PTS303H, the device model (its virtual time starts at 0 = server start)
    clock : callable returning seconds (monotonic), the only source of time
    baud : int > 0 [bit/s], pacing of bytes in both directions
    truth : text file for JSON lines, or None
    truth_period_s : float > 0 [s]
    link_path : optional path of a symlink to create pointing at the pty (a stable name)
    model_lock : optional lock held while the head model changes, for a caller that reads the model
        from another thread (a virtual lidar asking for the pose at each point's time).  The wait for
        input happens outside it: a lock held across the wait and taken again at once starves the
        reader (Python's locks are not fair), which on a busy machine silenced the lidar for seconds.
    """

    def __init__(
        self,
        head: PTS303H,
        clock: Callable[[], float],
        baud: int = 9600,
        truth: TextIO | None = None,
        truth_period_s: float = 0.02,
        link_path: str | None = None,
        model_lock=None,
    ) -> None:
        if not baud > 0:
            raise ValueError(f"baud={baud!r} must be > 0")
        if not truth_period_s > 0:
            raise ValueError(f"truth_period_s={truth_period_s!r} must be > 0")
        self.head = head
        self.clock = clock
        self.baud = baud
        self.truth = truth
        self.truth_period_s = truth_period_s
        self.link_path = link_path
        self.model_lock = model_lock if model_lock is not None else contextlib.nullcontext()
        self.byte_time_s = BITS_PER_BYTE / baud
        self._master: int | None = None
        self._slave: int | None = None
        self.path: str | None = None
        self._t0 = 0.0
        self._rx_free = 0.0
        self._tx_free = 0.0
        self._tx: deque[tuple[float, int]] = deque()
        self._next_truth = 0.0
        self.bytes_in = 0
        self.bytes_out = 0

    # -- lifecycle ---------------------------------------------------------------------------
    def open(self) -> str:
        """Create the pty (raw mode) and the optional symlink; return the path to print."""
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        tty.setraw(self._master)
        os.set_blocking(self._master, False)
        self.path = os.ttyname(self._slave)
        if self.link_path:
            tmp = f"{self.link_path}.tmp{os.getpid()}"
            os.symlink(self.path, tmp)
            os.replace(tmp, self.link_path)
        self._t0 = self.clock()
        return self.link_path or self.path

    @property
    def clock_zero(self) -> float:
        """The ``clock()`` reading that is virtual time 0 (truth ``t_s`` = clock() - this)."""
        return self._t0

    def now(self) -> float:
        """Virtual time of the head [s]."""
        return self.clock() - self._t0

    def close(self) -> None:
        if self._master is None:
            return
        self._write_truth(self.now())
        if self.link_path and os.path.islink(self.link_path):
            try:
                if os.readlink(self.link_path) == self.path:
                    os.unlink(self.link_path)
            except OSError:
                pass
        for fd in (self._master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass
        self._master = self._slave = None
        if self.truth is not None:
            self.truth.flush()

    def __enter__(self) -> "VirtualHeadServer":
        self.open()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- the loop ----------------------------------------------------------------------------
    def run(self, should_stop: Callable[[], bool], max_wait_s: float = 0.02) -> None:
        """Serve until ``should_stop()`` is true (checked at least every ``max_wait_s``)."""
        if self._master is None:
            self.open()
        while not should_stop():
            self.step(max_wait_s)

    def step(self, max_wait_s: float = 0.02) -> None:
        """One pass: wait for input or the next deadline (outside ``model_lock``), then read, reply
        and log truth (inside it)."""
        now = self.now()
        wait = min(max_wait_s, max(0.0, self._next_truth - now))
        if self._tx:
            wait = min(wait, max(0.0, self._tx[0][0] - now))
        try:
            readable, _, _ = select.select([self._master], [], [], wait)
        except InterruptedError:  # pragma: no cover - PEP 475 retries; kept for old kernels
            readable = []
        with self.model_lock:
            now = self.now()
            if readable:
                try:
                    data = os.read(self._master, 4096)
                except (BlockingIOError, InterruptedError):
                    data = b""
                except OSError:  # EIO: no process has the device side open (cannot happen: we do)
                    data = b""
                if data:
                    self._receive(data, now)
            self._flush_tx(self.now())
            now = self.now()
            if now >= self._next_truth:
                self._write_truth(now)
                self._next_truth = max(self._next_truth + self.truth_period_s, now)

    def power_cycle(self) -> None:
        """The head loses power and comes back now, while its pty (the link) stays up: the fault a
        daemon cannot see on the link (issue 26), only in the world its lidar sees.  Replies still
        queued are lost with the power."""
        with self.model_lock:
            now = self.now()
            self.head.power_cycle(now)
            self._tx.clear()
            self._write_truth(now)

    def _receive(self, data: bytes, now: float) -> None:
        times = []
        t = max(now, self._rx_free)
        for _ in data:
            t += self.byte_time_s
            times.append(t)
        self._rx_free = t
        self.bytes_in += len(data)
        for t_send, frame in self.head.receive(data, times):
            start = max(t_send, self._tx_free)
            for k, b in enumerate(frame, start=1):
                self._tx.append((start + k * self.byte_time_s, b))
            self._tx_free = start + len(frame) * self.byte_time_s

    def _flush_tx(self, now: float) -> None:
        out = bytearray()
        while self._tx and self._tx[0][0] <= now:
            out.append(self._tx.popleft()[1])
        if out:
            try:
                os.write(self._master, bytes(out))
                self.bytes_out += len(out)
            except (BlockingIOError, OSError):
                pass  # nobody reading and the pty buffer is full: the bytes are lost, as on a line

    def _write_truth(self, t: float) -> None:
        if self.truth is None:
            return
        st = self.head.state_at(max(t, self.head.t_now_s))
        self.truth.write(json.dumps(st.as_dict()) + "\n")
        self.truth.flush()


def read_truth(path: str) -> list[dict]:
    """The JSON lines of a truth file (a partial last line is skipped)."""
    rows = []
    with open(path) as fh:
        for line in fh:
            try:
                rows.append(json.loads(line))
            except json.JSONDecodeError:
                continue
    return rows


class ManualClock:
    """A clock the caller moves by hand (``t += dt``): runs the server in virtual time, e.g. for
    measuring a head from the outside deterministically."""

    def __init__(self, t: float = 0.0) -> None:
        self.t = float(t)

    def __call__(self) -> float:
        return self.t


def estimate_step_response(
    rows: list[dict], t_arrival_s: float, axis: str = "pan", window_s: float = 1.0
) -> dict:
    """Measure a speed step from truth rows, as an outside observer would.

    rows : truth JSON rows (``t_s``, ``<axis>_deg``, ``<axis>_speed_deg_s``), after one step
           command from rest whose last byte arrived at ``t_arrival_s``; the head must have
           settled before the last ``window_s`` of rows
    Returns ``speed_deg_s`` (angle change / time over the last ``window_s``), ``accel_deg_s2``
    (least-squares slope of speed over the 10-90 % part of the ramp; the ripple biases it by up
    to ~``ripple_rel``), ``dead_time_s`` (first row with nonzero speed minus ``t_arrival_s``: an
    upper bound, late by less than one truth period) and ``ramp_dead_time_s`` (where the ramp line
    crosses zero, minus ``t_arrival_s``).
    """
    import numpy as np

    t = np.array([r["t_s"] for r in rows])
    ang = np.array([r[f"{axis}_deg"] for r in rows])
    v = np.array([r[f"{axis}_speed_deg_s"] for r in rows])
    if axis == "pan":
        ang = np.unwrap(np.radians(ang)) * 180.0 / np.pi
    last = t >= t[-1] - window_s
    speed = (ang[last][-1] - ang[last][0]) / (t[last][-1] - t[last][0])
    ramp = (t > t_arrival_s) & (np.abs(v) > 0.1 * abs(speed)) & (np.abs(v) < 0.9 * abs(speed))
    moving = np.flatnonzero((t > t_arrival_s) & (v != 0))
    out = {
        "speed_deg_s": float(speed),
        "accel_deg_s2": float("nan"),
        "dead_time_s": float(t[moving[0]] - t_arrival_s) if moving.size else float("nan"),
        "ramp_dead_time_s": float("nan"),
    }
    if ramp.sum() >= 3:
        slope, icept = np.polyfit(t[ramp], v[ramp], 1)
        out["accel_deg_s2"] = float(abs(slope))
        out["ramp_dead_time_s"] = float(-icept / slope - t_arrival_s)
    return out
