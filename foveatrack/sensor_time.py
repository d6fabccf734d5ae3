"""Sensor time is evidence, not truth: per-packet checks of the lidar's point times.

A Livox stamps every point with its own clock (ns since power-on, or PTP/PPS time).  That clock
restarts from 0 when the unit restarts or its sync source changes, and a corrupted or foreign
packet can carry any time at all.  Drivers cut frames by these times (:class:`foveatrack.frames.FrameSlicer`),
so one wild time once asked for a 195 GiB frame-edge array, and a restarted unit's points were all
dropped as late.  :class:`SensorTimeGuard` sits between the client and the slicer:

* **continuity** -- consecutive points of one stream are ``1 / point_rate`` apart; packets lost on
  the way make a forward step, but never one longer than the host time that passed since the
  previous accepted points arrived, nor one to a time later than the host clock says the sensor's
  clock reads now (``host time - min over the stream of (host time - sensor time)``), each
  ``+ jump_tolerance_s``: the second rule keeps a stalled receiver (packets read late, then a lidar
  that skipped time) from reading as a jump.  A backward step (beyond ``back_tolerance_s``) or a
  forward step that breaks both rules starts a new *segment*;
* a segment that is not continuous with the stream is held as a **candidate** epoch.  If the points
  that follow continue the candidate for ``confirm_s`` of sensor time, the sensor clock really jumped
  (a restart, a sync change): the guard **re-anchors** (``epoch`` + 1, the host - sensor offset starts
  again from the candidate's packets) and hands the candidate's points on.  If the stream carries on
  where it was instead, the candidate was a bad packet: its points are dropped and counted.

Nothing here allocates by a time difference: the work is ``O(points)`` whatever the times.

Counters (``counters``): ``clock_jumps`` (re-anchors), ``bad_time_segments`` / ``bad_time_points``
(dropped as wrong times), and, with the point rate known, ``lost_slots``: the time slots missing
inside the stream (a Livox v1 packet has no sequence number, but its points are one slot apart, so a
step of k slot periods is k - 1 lost slots: lost packets, counted where they were lost).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np

JUMP_TOLERANCE_S = 0.2    # host scheduling slack on top of the elapsed host time [s]
BACK_TOLERANCE_S = 1e-3   # Livox packets arrive in order; a step back beyond this is a new clock [s]
CONFIRM_S = 0.02          # sensor time a candidate must run continuously to be a new clock [s]
                          # (a Mid-40 packet spans 1 ms: 20 packets in a row cannot be chance)


@dataclass
class Accepted:
    """Points handed on: ``xyz (n, 3)``, ``t_ns (n,)``, ``reflectivity (n,)``, and the ``epoch`` they belong to."""

    xyz: np.ndarray
    t_ns: np.ndarray
    reflectivity: np.ndarray
    epoch: int

    def __len__(self) -> int:
        return int(self.t_ns.shape[0])


@dataclass
class ClockJump:
    """A confirmed re-anchor: the stream's last sensor time before [s], the new clock's first [s],
    and the host time it was confirmed at [s, monotonic]."""

    epoch: int
    last_t_s: float | None
    new_t_s: float
    host_s: float

    def as_event(self) -> dict:
        return {"event": "clock_jump", "epoch": self.epoch, "last_t_s": self.last_t_s, "new_t_s": self.new_t_s,
                "jump_s": None if self.last_t_s is None else self.new_t_s - self.last_t_s}


class SensorTimeGuard:
    """Split point batches into time-continuous segments and keep one stream (see the module docstring).

    jump_tolerance_s : > 0 [s], slack on top of the host time elapsed for a forward step
    back_tolerance_s : >= 0 [s], the largest step back still read as the same stream
    confirm_s : > 0 [s], sensor time a candidate new clock must run to be accepted
    point_rate_hz : > 0 [slots/s] or None, the sensor's slot rate (counts ``lost_slots``)
    """

    def __init__(self, jump_tolerance_s: float = JUMP_TOLERANCE_S, back_tolerance_s: float = BACK_TOLERANCE_S,
                 confirm_s: float = CONFIRM_S, point_rate_hz: float | None = None):
        self.slot_ns = None if not point_rate_hz else 1e9 / point_rate_hz
        self.jump_ns = int(jump_tolerance_s * 1e9)
        self.back_ns = int(back_tolerance_s * 1e9)
        self.confirm_ns = int(confirm_s * 1e9)
        self.epoch = 0
        self.last_t_ns: int | None = None      # the stream's newest accepted point time
        self.last_host_s: float | None = None  # host time its batch arrived
        self.min_off_ns: int | None = None     # min (host - sensor) time of this clock's stream [ns]
        self._cand: list[tuple[np.ndarray, np.ndarray, np.ndarray, float]] = []
        self._cand_first_ns = self._cand_last_ns = 0
        self.counters: Counter = Counter(clock_jumps=0, bad_time_segments=0, bad_time_points=0, lost_slots=0)
        self.jumps: list[ClockJump] = []        # confirmed re-anchors not yet taken (take_jumps)

    # ------------------------------------------------------------------------------------------
    def _fwd_limit_ns(self, host_s: float, since_s: float | None) -> int:
        elapsed = 0.0 if since_s is None else max(0.0, host_s - since_s)
        return int(elapsed * 1e9) + self.jump_ns

    def _sensor_now_ns(self, host_s: float) -> int | None:
        """The latest time the stream's sensor clock can read at host time ``host_s`` (+ tolerance)."""
        return None if self.min_off_ns is None else int(host_s * 1e9) - self.min_off_ns + self.jump_ns

    def _continues(self, last_ns: int | None, since_s: float | None, first_ns: int, host_s: float,
                   now_ns: int | None = None) -> bool:
        if last_ns is None:
            return True
        step = first_ns - last_ns
        if step < -self.back_ns:
            return False
        return step <= self._fwd_limit_ns(host_s, since_s) or (now_ns is not None and first_ns <= now_ns)

    def push(self, xyz, t_ns, reflectivity, host_s: float) -> list[Accepted]:
        """The accepted points of one batch that arrived at host time ``host_s`` [s] (monotonic), in
        order; a re-anchor shows as a new ``epoch`` in what follows (and in :attr:`jumps`)."""
        t_ns = np.asarray(t_ns, dtype=np.int64).reshape(-1)
        if t_ns.size == 0:
            return []
        xyz = np.asarray(xyz).reshape(-1, 3)
        refl = np.asarray(reflectivity).reshape(-1)
        d = np.diff(t_ns)
        lim = self._fwd_limit_ns(host_s, self.last_host_s)   # any step inside one poll
        fwd = d > lim
        now_ns = self._sensor_now_ns(host_s)
        if now_ns is not None:
            fwd &= t_ns[1:] > now_ns
        cuts = np.flatnonzero((d < -self.back_ns) | fwd) + 1
        bounds = np.concatenate(([0], cuts, [t_ns.size]))
        out: list[Accepted] = []
        for a, b in zip(bounds[:-1], bounds[1:]):
            self._segment(xyz[a:b], t_ns[a:b], refl[a:b], host_s, out)
        return out

    def _segment(self, xyz, t, refl, host_s: float, out: list[Accepted]) -> None:
        first, last = int(t[0]), int(t[-1])
        if self._continues(self.last_t_ns, self.last_host_s, first, host_s, self._sensor_now_ns(host_s)):
            if self._cand:
                # the stream carried on where it was: the candidate was wrong times
                self._drop_candidate()
            self._accept(xyz, t, refl, host_s, out)
            return
        if self._cand and self._continues(self._cand_last_ns, self._cand[-1][3], first, host_s):
            self._cand.append((xyz, t, refl, host_s))
            self._cand_last_ns = last
        else:
            if self._cand:
                self._drop_candidate()
            self._cand = [(xyz, t, refl, host_s)]
            self._cand_first_ns, self._cand_last_ns = first, last
        if self._cand_last_ns - self._cand_first_ns >= self.confirm_ns:
            self.epoch += 1
            self.counters["clock_jumps"] += 1
            self.jumps.append(ClockJump(self.epoch, None if self.last_t_ns is None else self.last_t_ns * 1e-9,
                                        self._cand_first_ns * 1e-9, host_s))
            cand, self._cand = self._cand, []
            self.last_t_ns = self.min_off_ns = None
            for cx, ct, cr, ch in cand:
                self._accept(cx, ct, cr, ch, out)

    def _accept(self, xyz, t, refl, host_s, out: list[Accepted]) -> None:
        if self.slot_ns is not None:
            d = np.diff(t) if self.last_t_ns is None else np.diff(t, prepend=self.last_t_ns)
            big = d[d > 1.5 * self.slot_ns]
            if big.size:
                self.counters["lost_slots"] += int(np.sum(np.rint(big / self.slot_ns) - 1))
        self.last_t_ns = int(t[-1])
        self.last_host_s = host_s
        off = int(host_s * 1e9) - self.last_t_ns
        self.min_off_ns = off if self.min_off_ns is None else min(self.min_off_ns, off)
        if out and out[-1].epoch == self.epoch:
            prev = out[-1]
            out[-1] = Accepted(np.concatenate([prev.xyz, xyz]), np.concatenate([prev.t_ns, t]),
                               np.concatenate([prev.reflectivity, refl]), self.epoch)
        else:
            out.append(Accepted(xyz, t, refl, self.epoch))

    def _drop_candidate(self) -> None:
        self.counters["bad_time_segments"] += len(self._cand)
        self.counters["bad_time_points"] += sum(len(c[1]) for c in self._cand)
        self._cand = []

    @property
    def held_points(self) -> int:
        return sum(len(c[1]) for c in self._cand)

    def take_jumps(self) -> list[ClockJump]:
        out, self.jumps = self.jumps, []
        return out
