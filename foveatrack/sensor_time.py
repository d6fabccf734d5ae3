"""Sensor time is evidence, not truth: per-packet checks of the lidar's point times.

A Livox stamps every point with its own clock (ns since power-on, or PTP/PPS time).  That clock
restarts from 0 when the unit restarts or its sync source changes, and the network can deliver a
packet late (overtaken by its successor), twice, again much later (a replay), or a corrupted or
foreign packet with any time at all.  Drivers cut frames by these times
(:class:`foveatrack.frames.FrameSlicer`), so one wild time once asked for a 195 GiB frame-edge array,
a restarted unit's points were all dropped as late, and (issue 26) one packet 50 ms ahead, a burst of
5 s-old packets or a re-sent one each read as a new clock.  :class:`SensorTimeGuard` sits between the
client and the slicer.  A batch is cut into *segments* at every step back in time and every forward
step longer than a lost packet or two; each segment is then one of:

* **continuation** -- after the newest accepted point ``N`` and no further ahead than a few lost
  packets (``contiguous_s``) or than the sensor clock can read now (host time minus the smallest
  host - sensor offset seen, ``+ forward_tolerance_s``): accepted.  Real points never lead the
  sensor's clock, and a lidar that skipped time while the receiver stalled is still within it;
* **late** -- at or before ``N`` but in a gap of the stream (slots counted lost when the later
  packet came, within the last ``memory_s``): a real packet overtaken on the way.  Accepted; the
  lost slots it fills are withdrawn (``late_points``).  Accepted points are held back
  ``reorder_s`` of sensor time so a packet overtaken by its neighbour is put back in order before
  the slicer cuts a frame;
* **duplicate** -- times already accepted (within ``memory_s``): a duplicated or re-sent packet,
  dropped (``duplicate_points``);
* **stale** -- older than anything remembered, or before the stream began (``stale_points``); or
  **early** -- ahead of the sensor clock's now (``early_points``).  Both are wrong times
  (``bad_time_points`` = stale + early).

A segment that is not a continuation or late, and only such, may be the first of a new clock: it is
held as a **candidate**.  The candidate becomes the stream (**re-anchor**: ``epoch`` + 1, the host -
sensor offset measured afresh, its points handed on) only if it runs on by itself, continuous in its
own time, for ``confirm_s`` of *host* time with a sensor span of at least half that, and nothing of
the old stream arrives meanwhile.  A burst of old packets spans no host time, and a re-sent or early
packet is followed by the stream carrying on; in both cases the candidate's points are counted under
their kind and dropped.  A restarted lidar is re-anchored ``confirm_s`` (0.1 s) after its first
packet.  A candidate ahead of ``N`` by no more than the host time that passed is the same clock
after a long gap (accepted, no re-anchor).

Nothing here allocates by a time difference: the work is ``O(points)`` whatever the times, and what
is remembered is bounded (``memory_s`` of accepted intervals, at most ``MAX_INTERVALS``).

Counters (``counters``): ``clock_jumps`` (re-anchors); ``late_segments/points`` (accepted out of
order); ``duplicate_segments/points``, ``stale_segments/points``, ``early_segments/points``
(dropped); ``bad_time_segments/points`` (stale + early); and, with the point rate known,
``lost_slots``: the time slots missing inside the stream (a Livox v1 packet has no sequence number,
but its points are one slot apart, so a step of k slot periods is k - 1 lost slots).
"""

from __future__ import annotations

import bisect
from collections import Counter
from dataclasses import dataclass

import numpy as np

FORWARD_TOLERANCE_S = 0.01  # a point may lead the sensor clock's estimated now by this much [s]
CONTIGUOUS_S = 0.01         # a forward step this short is the stream going on (lost packets) [s]
JUMP_TOLERANCE_S = 0.2      # host scheduling slack on the host time elapsed: a lone candidate ahead by
                            # no more than that is the same clock after a gap [s]
CONFIRM_S = 0.1             # host time a candidate clock must run alone to be a new clock [s]
MEMORY_S = 1.0              # accepted times remembered (duplicates, late packets) [s]
REORDER_S = 0.002           # accepted points held back (sensor time) to put overtaken packets in order [s]
MIN_CUT_S = 0.001           # a batch is cut at forward steps longer than this (and 1.5 slots) [s]
DRIFT_PPM = 200.0           # the host - sensor offset's minimum may rise this fast [ppm]
MAX_INTERVALS = 4096        # accepted intervals remembered at most (a stream with much loss)
_KINDS = ("duplicate", "stale", "early")


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


class _Candidate:
    """Segments that may be a new clock: points, their kinds, and the candidate's own clock."""

    def __init__(self):
        self.segs: list = []              # (xyz, t, refl, host_s, {kind: points})
        self.first_ns = self.last_ns = 0
        self.host0_s = self.last_host_s = 0.0
        self.min_off_ns = 0

    def add(self, xyz, t, refl, host_s: float, kinds: dict) -> None:
        if not self.segs:
            self.first_ns, self.host0_s = int(t[0]), host_s
            self.min_off_ns = int(host_s * 1e9) - int(t[-1])
        self.segs.append((xyz, t, refl, host_s, kinds))
        self.last_ns, self.last_host_s = int(t[-1]), host_s
        self.min_off_ns = min(self.min_off_ns, int(host_s * 1e9) - self.last_ns)

    @property
    def points(self) -> int:
        return sum(len(s[1]) for s in self.segs)


class SensorTimeGuard:
    """Split point batches into time-continuous segments and keep one stream (see the module docstring).

    forward_tolerance_s : >= 0 [s], how far a point may lead the sensor clock's estimated now
    contiguous_s : >= 0 [s], the longest forward step read as lost packets whatever the clock says
    jump_tolerance_s : > 0 [s], slack on the host time elapsed for a lone candidate ahead of the stream
    confirm_s : > 0 [s], host time a candidate new clock must run alone to be accepted
    memory_s : > 0 [s], accepted times remembered to tell a duplicate or late packet
    reorder_s : >= 0 [s], accepted points held back so an overtaken packet is put in order
    point_rate_hz : > 0 [slots/s] or None, the sensor's slot rate (counts ``lost_slots``)
    """

    def __init__(self, forward_tolerance_s: float = FORWARD_TOLERANCE_S, contiguous_s: float = CONTIGUOUS_S,
                 jump_tolerance_s: float = JUMP_TOLERANCE_S, confirm_s: float = CONFIRM_S,
                 memory_s: float = MEMORY_S, reorder_s: float = REORDER_S, point_rate_hz: float | None = None):
        self.slot_ns = None if not point_rate_hz else 1e9 / point_rate_hz
        self.fwd_ns = int(forward_tolerance_s * 1e9)
        self.contig_ns = int(contiguous_s * 1e9)
        self.jump_ns = int(jump_tolerance_s * 1e9)
        self.confirm_s = float(confirm_s)
        self.memory_ns = int(memory_s * 1e9)
        self.reorder_ns = int(reorder_s * 1e9)
        self.epoch = 0
        self.last_t_ns: int | None = None      # the stream's newest accepted point time (N)
        self.last_host_s: float | None = None  # host time its batch arrived
        self.min_off_ns: int | None = None     # min (host - sensor) time of this clock's stream [ns]
        self._starts: list[int] = []           # accepted intervals [start, end] of the last memory_s
        self._ends: list[int] = []
        self._tail: list = []                  # accepted (xyz, t, refl) not yet handed on
        self._tail_sorted = True               # ... in time order (no late packet among them)
        self._cand = _Candidate()
        self.accepted_points = 0
        self.counters: Counter = Counter(
            clock_jumps=0, bad_time_segments=0, bad_time_points=0, lost_slots=0, late_segments=0, late_points=0,
            **{f"{k}_{w}": 0 for k in _KINDS for w in ("segments", "points")})
        self.jumps: list[ClockJump] = []        # confirmed re-anchors not yet taken (take_jumps)

    # ------------------------------------------------------------------------------------------ time
    @property
    def offset_s(self) -> float | None:
        """min over this clock's accepted batches of (host time - newest point time) [s]."""
        return None if self.min_off_ns is None else self.min_off_ns * 1e-9

    def _missing(self, a_ns: int, b_ns: int) -> int:
        """Slots missing between accepted points at ``a_ns`` and ``b_ns`` (0 without a slot rate)."""
        if self.slot_ns is None or b_ns - a_ns <= 1.5 * self.slot_ns:
            return 0
        return int(round((b_ns - a_ns) / self.slot_ns)) - 1

    def _missing_inside(self, t: np.ndarray) -> int:
        if self.slot_ns is None or t.size < 2:
            return 0
        d = np.diff(t)
        big = d[d > 1.5 * self.slot_ns]
        return int(np.sum(np.rint(big / self.slot_ns) - 1)) if big.size else 0

    def _continues(self, first_ns: int, host_s: float) -> bool:
        """Does a segment starting at ``first_ns`` (after N) go on with the stream?"""
        if first_ns - self.last_t_ns <= self.contig_ns:
            return True
        return first_ns <= int(host_s * 1e9) - self.min_off_ns + self.fwd_ns

    # ------------------------------------------------------------------------------------------ push
    def push(self, xyz, t_ns, reflectivity, host_s: float) -> list[Accepted]:
        """The accepted points of one batch that arrived at host time ``host_s`` [s] (monotonic), in
        time order (but for a packet later than ``reorder_s``); a re-anchor shows as a new ``epoch``
        in what follows (and in :attr:`jumps`).  The newest ``reorder_s`` are handed on by a later
        push (or :meth:`flush`)."""
        t_ns = np.asarray(t_ns, dtype=np.int64).reshape(-1)
        if t_ns.size == 0:
            return []
        xyz = np.asarray(xyz).reshape(-1, 3)
        refl = np.asarray(reflectivity).reshape(-1)
        d = np.diff(t_ns)
        cut_ns = max(MIN_CUT_S * 1e9, 1.5 * self.slot_ns if self.slot_ns else 0.0)
        cuts = np.flatnonzero((d < 0) | (d > cut_ns)) + 1
        out: list[Accepted] = []
        if cuts.size == 0:
            self._segment(xyz, t_ns, refl, host_s, out)
        else:
            bounds = np.concatenate(([0], cuts, [t_ns.size]))
            for a, b in zip(bounds[:-1].tolist(), bounds[1:].tolist()):
                self._segment(xyz[a:b], t_ns[a:b], refl[a:b], host_s, out)
        self._emit(out, None if self.last_t_ns is None else self.last_t_ns - self.reorder_ns)
        return out

    def flush(self) -> list[Accepted]:
        """Hand on every accepted point still held back (the stream ended)."""
        out: list[Accepted] = []
        self._emit(out, None)
        return out

    def _segment(self, xyz, t, refl, host_s: float, out: list[Accepted]) -> None:
        if self.last_t_ns is None:                 # the first points: the stream starts here
            self._accept(xyz, t, refl, host_s)
            return
        n_old = int(np.searchsorted(t, self.last_t_ns, side="right"))
        if n_old == 0:
            if self._continues(int(t[0]), host_s):
                self._accept(xyz, t, refl, host_s)
            else:
                self._offer(xyz, t, refl, host_s, {"early": len(t)}, out)
            return
        # points at or before N: in a gap of the stream (late), on accepted times (duplicate), or
        # older than remembered (stale)
        to = t[:n_old]
        st = np.asarray(self._starts, dtype=np.int64)
        en = np.asarray(self._ends, dtype=np.int64)
        i = np.searchsorted(st, to, side="right") - 1
        covered = (i >= 0) & (to <= en[np.maximum(i, 0)])
        stale = (i < 0)
        late = ~covered & ~stale
        n_dup, n_stale = int(covered.sum()), int(stale.sum())
        if not late.any() and n_old == len(t):
            kinds = {k: n for k, n in (("duplicate", n_dup), ("stale", n_stale)) if n}
            self._offer(xyz, t, refl, host_s, kinds, out)
            return
        # part of it is real (late, or newer than N): the rest is counted and dropped here
        self._count({k: n for k, n in (("duplicate", n_dup), ("stale", n_stale)) if n})
        if late.any():
            self._fill(xyz[:n_old][late], to[late], refl[:n_old][late], i[late])
        if n_old < len(t):
            self._segment(xyz[n_old:], t[n_old:], refl[n_old:], host_s, out)

    def _offer(self, xyz, t, refl, host_s: float, kinds: dict, out: list[Accepted]) -> None:
        """A segment that is neither the stream nor a late part of it: a candidate new clock."""
        c = self._cand
        if c.segs:
            first = int(t[0])
            goes_on = first > c.last_ns and (first - c.last_ns <= self.contig_ns
                                             or first <= int(host_s * 1e9) - c.min_off_ns + self.fwd_ns)
            if not goes_on:
                self._drop_candidate()
                c = self._cand
        c.add(xyz, t, refl, host_s, kinds)
        if c.last_host_s - c.host0_s >= self.confirm_s and (c.last_ns - c.first_ns) * 1e-9 >= 0.5 * self.confirm_s:
            self._confirm(out)

    def _confirm(self, out: list[Accepted]) -> None:
        c, self._cand = self._cand, _Candidate()
        ahead = c.first_ns - self.last_t_ns
        if 0 < ahead <= (c.host0_s - self.last_host_s) * 1e9 + self.jump_ns:
            # the same clock after a gap the host time allows (its offset had not settled): go on
            for cx, ct, cr, ch, _ in c.segs:
                self._accept(cx, ct, cr, ch)
            return
        self._emit(out, None)                  # the old clock's points first, all of them
        self.epoch += 1
        self.counters["clock_jumps"] += 1
        self.jumps.append(ClockJump(self.epoch, self.last_t_ns * 1e-9, c.first_ns * 1e-9, c.last_host_s))
        self.last_t_ns = self.last_host_s = self.min_off_ns = None
        self._starts, self._ends = [], []
        for cx, ct, cr, ch, _ in c.segs:
            if self.last_t_ns is None or int(ct[0]) > self.last_t_ns:
                self._accept(cx, ct, cr, ch)
            else:                              # the candidate's own overlaps: duplicates
                self._count({"duplicate": len(ct)})

    def _drop_candidate(self) -> None:
        for *_, kinds in self._cand.segs:
            self._count(kinds)
        self._cand = _Candidate()

    def _count(self, kinds: dict) -> None:
        if not kinds:
            return
        main = max(kinds, key=kinds.get)       # a segment is counted once, under its main kind
        self.counters[f"{main}_segments"] += 1
        for k, n in kinds.items():
            self.counters[f"{k}_points"] += n
        bad = kinds.get("stale", 0) + kinds.get("early", 0)
        if bad:
            self.counters["bad_time_points"] += bad
            self.counters["bad_time_segments"] += main != "duplicate"

    # ------------------------------------------------------------------------------------------ accept
    def _accept(self, xyz, t, refl, host_s: float) -> None:
        """Points after N that go on with the stream."""
        if self._cand.segs:                    # the stream carried on: the candidate was wrong times
            self._drop_candidate()
        first, last = int(t[0]), int(t[-1])
        if self.last_t_ns is not None:
            self.counters["lost_slots"] += self._missing(self.last_t_ns, first)
        # remembered as runs without a missing slot: a late packet may still fill any hole
        gap_ok = 1.5 * self.slot_ns if self.slot_ns else MIN_CUT_S * 1e9
        d = np.diff(t)
        holes = np.flatnonzero(d > gap_ok)
        if holes.size:
            if self.slot_ns is not None:
                self.counters["lost_slots"] += int(np.sum(np.rint(d[holes] / self.slot_ns) - 1))
            run_starts = [first, *t[holes + 1].tolist()]
            run_ends = [*t[holes].tolist(), last]
        else:
            run_starts, run_ends = [first], [last]
        if self._ends and run_starts[0] - self._ends[-1] <= gap_ok:
            self._ends[-1] = run_ends[0]
            run_starts, run_ends = run_starts[1:], run_ends[1:]
        self._starts.extend(run_starts)
        self._ends.extend(run_ends)
        horizon = last - self.memory_ns
        while len(self._starts) > 1 and (self._ends[0] < horizon or len(self._starts) > MAX_INTERVALS):
            del self._starts[0], self._ends[0]
        self._starts[0] = max(self._starts[0], min(horizon, self._ends[0]))   # older is "stale"
        off = int(host_s * 1e9) - last
        if self.min_off_ns is None:
            self.min_off_ns = off
        else:
            # the smallest offset, let rise as fast as two clocks can drift apart (a sensor clock slower
            # than the host's would otherwise leave the estimated now ahead of it, further every hour)
            since = max(0.0, host_s - (self.last_host_s if self.last_host_s is not None else host_s))
            self.min_off_ns = min(off, self.min_off_ns + int(since * DRIFT_PPM * 1e3))
        self.last_t_ns, self.last_host_s = last, host_s
        self._keep(xyz, t, refl)

    def _fill(self, xyz, t, refl, gap_index: np.ndarray) -> None:
        """Late points in the gaps after the intervals ``gap_index``: accepted, the slots they fill
        no longer counted lost."""
        self.counters["late_segments"] += 1
        self.counters["late_points"] += len(t)
        for g in np.unique(gap_index)[::-1].tolist():     # from the last gap: indices stay valid
            tg = t[gap_index == g]
            a, b = self._ends[g], self._starts[g + 1]
            before = self._missing(a, b)
            after = self._missing(a, int(tg[0])) + self._missing_inside(tg) + self._missing(int(tg[-1]), b)
            self.counters["lost_slots"] -= before - after
            self._starts.insert(g + 1, int(tg[0]))
            self._ends.insert(g + 1, int(tg[-1]))
            # a gap filled whole joins its neighbours: a stream of swapped packets stays one interval
            if self._missing(int(tg[-1]), b) == 0 and self._missing_inside(tg) == 0:
                self._ends[g + 1] = self._ends[g + 2]
                del self._starts[g + 2], self._ends[g + 2]
            if self._missing(a, int(tg[0])) == 0:
                self._ends[g] = self._ends[g + 1]
                del self._starts[g + 1], self._ends[g + 1]
        self._keep(xyz, t, refl, in_order=False)

    def _keep(self, xyz, t, refl, in_order: bool = True) -> None:
        self.accepted_points += len(t)
        self._tail.append((xyz, t, refl))
        self._tail_sorted &= in_order

    def _emit(self, out: list[Accepted], upto_ns: int | None) -> None:
        """Hand on the held points at or before ``upto_ns`` (None: all), in time order."""
        if not self._tail:
            return
        if len(self._tail) == 1:
            xyz, t, refl = self._tail[0]
        else:
            xyz = np.concatenate([p[0] for p in self._tail])
            t = np.concatenate([p[1] for p in self._tail])
            refl = np.concatenate([p[2] for p in self._tail])
        if not self._tail_sorted:               # a late packet is among them
            o = np.argsort(t, kind="stable")
            xyz, t, refl = xyz[o], t[o], refl[o]
            self._tail_sorted = True
        n = t.size if upto_ns is None else int(np.searchsorted(t, upto_ns, side="right"))
        self._tail = [(xyz[n:], t[n:], refl[n:])] if n < t.size else []
        if n == 0:
            return
        if out and out[-1].epoch == self.epoch:
            prev = out[-1]
            out[-1] = Accepted(np.concatenate([prev.xyz, xyz[:n]]), np.concatenate([prev.t_ns, t[:n]]),
                               np.concatenate([prev.reflectivity, refl[:n]]), self.epoch)
        else:
            out.append(Accepted(xyz[:n], t[:n], refl[:n], self.epoch))

    @property
    def held_points(self) -> int:
        """Points held: a candidate's and the reorder tail's."""
        return self._cand.points + sum(len(p[1]) for p in self._tail)

    def take_jumps(self) -> list[ClockJump]:
        out, self.jumps = self.jumps, []
        return out
