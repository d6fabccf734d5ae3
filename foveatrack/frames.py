"""Slicing the timestamped point stream into fixed-period frames (paper Appendix D.2).

Algorithm 1 "runs in real-time at 10Hz and slices the lidar point stream into a frame (i.e. P) for
every 100ms".  :class:`FrameSlicer` does that slicing for any driver (closed-loop simulator, replay,
daemon): it is fed batches of points of any size with per-point timestamps and emits complete frames.

Conventions
-----------
* Points are in the lidar frame: X forward (optical axis), Y left, Z up, metres, float64.
* Time is integer nanoseconds per point (``t_ns``, int64).  Frame ``k`` covers the half-open
  interval ``[t0_ns + k*period_ns, t0_ns + (k+1)*period_ns)`` where ``t0_ns`` is the first point's
  time floored to a multiple of the period (so frames of two runs line up on the same clock).
  A point exactly on a boundary belongs to the later frame; every point lands in exactly one frame.
* ``period_ns = round(1e9 / rate_hz)``: integer arithmetic, so no point is lost or counted twice by
  floating-point rounding at a boundary.
* Points are expected in non-decreasing time *per batch and across batches up to* ``max_lateness_ns``
  (Livox packets arrive in order).  A point older than the last emitted frame is counted in
  :attr:`FrameSlicer.late_points` and dropped (it can no longer be placed in an emitted frame).
* Nothing is allocated by a time difference: a point more than ``max_gap_frames`` periods past the
  current frame (a wild timestamp; once a 195 GiB edge array) restarts the slicer at that point's
  frame, dropping what was buffered (:attr:`FrameSlicer.restarts`, :attr:`FrameSlicer.gap_dropped_points`).
  Live drivers filter such times first (:mod:`foveatrack.sensor_time`); this is the last line.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Frame:
    """One frame ``P`` of lidar points.

    Parameters
    ----------
    t_start_s, t_end_s : float [s]
        The frame's half-open interval ``[t_start_s, t_end_s)``.
    xyz : (N, 3) float64 [m], C-contiguous (copied if given otherwise)
        Points in the lidar frame (X forward, Y left, Z up).  May contain NaN/inf and (0,0,0)
        "no return" points; detection ignores them.
    t_ns : (N,) int64 [ns], contiguous
        Per-point timestamps, all inside the interval.
    reflectivity : (N,) uint8 or None
        Livox reflectivity byte per point, if known.
    """

    t_start_s: float
    t_end_s: float
    xyz: np.ndarray
    t_ns: np.ndarray
    reflectivity: np.ndarray | None = None

    def __post_init__(self) -> None:
        # Contiguous, so the tracker's box kernel takes them as they are (no check per frame).
        xyz = np.ascontiguousarray(self.xyz, dtype=np.float64).reshape(-1, 3)
        t_ns = np.ascontiguousarray(self.t_ns, dtype=np.int64).reshape(-1)
        if xyz.shape[0] != t_ns.shape[0]:
            raise ValueError(f"xyz has {xyz.shape[0]} points but t_ns has {t_ns.shape[0]}")
        object.__setattr__(self, "xyz", xyz)
        object.__setattr__(self, "t_ns", t_ns)
        if self.reflectivity is not None:
            refl = np.asarray(self.reflectivity).reshape(-1)
            if refl.shape[0] != xyz.shape[0]:
                raise ValueError("reflectivity length differs from the number of points")
            object.__setattr__(self, "reflectivity", refl)

    @property
    def n_points(self) -> int:
        return int(self.xyz.shape[0])

    @property
    def t_mid_s(self) -> float:
        return 0.5 * (self.t_start_s + self.t_end_s)

    @property
    def duration_s(self) -> float:
        return self.t_end_s - self.t_start_s


@dataclass
class FrameSlicer:
    """Cut a stream of timestamped point batches into frames of ``1/rate_hz`` seconds.

    ``push(xyz, t_ns, reflectivity=None)`` returns the frames completed by that batch (a frame is
    complete once a point at or after its end time has been seen); ``flush()`` returns the partial
    last frame.  Empty intervals between points still produce (empty) frames, so the tracker sees a
    frame every period even when nothing returns (e.g. the sky).

    Parameters
    ----------
    rate_hz : float > 0 [Hz]
        Frame rate (paper: 10 Hz).
    max_gap_frames : int >= 1
        The most (empty) frames one push may complete; beyond, the slicer restarts (see the module docstring).
    """

    rate_hz: float = 10.0
    max_gap_frames: int = 600
    late_points: int = field(default=0, init=False)
    restarts: int = field(default=0, init=False)
    gap_dropped_points: int = field(default=0, init=False)
    _t0_ns: int | None = field(default=None, init=False, repr=False)
    _next_start_ns: int | None = field(default=None, init=False, repr=False)
    _buf_xyz: list = field(default_factory=list, init=False, repr=False)
    _buf_t: list = field(default_factory=list, init=False, repr=False)
    _buf_r: list = field(default_factory=list, init=False, repr=False)
    _has_refl: bool | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        if not (self.rate_hz > 0 and np.isfinite(self.rate_hz)):
            raise ValueError(f"rate_hz must be a positive finite number, got {self.rate_hz!r}")

    @property
    def period_ns(self) -> int:
        return int(round(1e9 / self.rate_hz))

    def push(self, xyz, t_ns, reflectivity=None) -> list[Frame]:
        xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
        t_ns = np.asarray(t_ns, dtype=np.int64).reshape(-1)
        if xyz.shape[0] != t_ns.shape[0]:
            raise ValueError(f"xyz has {xyz.shape[0]} points but t_ns has {t_ns.shape[0]}")
        if reflectivity is not None:
            reflectivity = np.asarray(reflectivity).reshape(-1)
            if reflectivity.shape[0] != t_ns.shape[0]:
                raise ValueError("reflectivity length differs from the number of points")
        if self._has_refl is None and t_ns.size:
            self._has_refl = reflectivity is not None
        if t_ns.size == 0:
            return []
        if self._has_refl and reflectivity is None:
            reflectivity = np.zeros(t_ns.shape[0], dtype=np.uint8)
        period = self.period_ns
        if self._next_start_ns is None:
            self._t0_ns = (int(t_ns.min()) // period) * period
            self._next_start_ns = self._t0_ns
        # Drop points that belong to frames already emitted.
        ok = t_ns >= self._next_start_ns
        if not ok.all():
            self.late_points += int((~ok).sum())
            xyz, t_ns = xyz[ok], t_ns[ok]
            if reflectivity is not None:
                reflectivity = reflectivity[ok]
        self._buf_xyz.append(xyz)
        self._buf_t.append(t_ns)
        if self._has_refl:
            self._buf_r.append(reflectivity)
        t_max = max(int(t.max()) for t in self._buf_t if t.size) if any(t.size for t in self._buf_t) \
            else self._next_start_ns
        n_complete = (t_max - self._next_start_ns) // period  # frames whose end <= t_max
        if n_complete > self.max_gap_frames:
            self._restart_at(t_max)
            return []
        if n_complete <= 0:
            return []
        return self._emit(int(n_complete))

    def flush(self) -> list[Frame]:
        """Emit the partial frame holding the remaining buffered points (if any)."""
        if self._next_start_ns is None or not any(t.size for t in self._buf_t):
            return []
        t_max = max(int(t.max()) for t in self._buf_t if t.size)
        n = (t_max - self._next_start_ns) // self.period_ns + 1
        if n > self.max_gap_frames:
            self._restart_at(t_max)
            n = 1
        return self._emit(int(n))

    def reset(self) -> None:
        """Forget the stream (a driver whose sensor clock restarted): the next point starts frame 0 afresh."""
        self._t0_ns = self._next_start_ns = None
        self._buf_xyz, self._buf_t, self._buf_r = [], [], []

    def _restart_at(self, t_ns: int) -> None:
        """Start again at the frame holding ``t_ns``, keeping only the buffered points in it."""
        period = self.period_ns
        start = (t_ns // period) * period
        self.restarts += 1
        kept_x, kept_t, kept_r = [], [], []
        for k, t in enumerate(self._buf_t):
            keep = t >= start
            self.gap_dropped_points += int((~keep).sum())
            kept_t.append(t[keep])
            kept_x.append(self._buf_xyz[k][keep])
            if self._has_refl:
                kept_r.append(self._buf_r[k][keep])
        self._buf_xyz, self._buf_t, self._buf_r = kept_x, kept_t, kept_r
        self._next_start_ns = start

    def _emit(self, n_frames: int) -> list[Frame]:
        period = self.period_ns
        xyz = np.concatenate(self._buf_xyz) if self._buf_xyz else np.empty((0, 3))
        t = np.concatenate(self._buf_t) if self._buf_t else np.empty(0, np.int64)
        refl = np.concatenate(self._buf_r) if (self._has_refl and self._buf_r) else None
        # packets come in time order nearly always: the gathers of a reorder cost 1-2 ms a frame at
        # 480 k points/s (bench_daemon_frame), the test 0.02 ms
        if t.size > 1 and not bool(np.all(t[1:] >= t[:-1])):
            order = np.argsort(t, kind="stable")
            xyz, t = xyz[order], t[order]
            if refl is not None:
                refl = refl[order]
        start = self._next_start_ns
        edges = start + period * np.arange(n_frames + 1, dtype=np.int64)
        idx = np.searchsorted(t, edges, side="left")
        frames = []
        for k in range(n_frames):
            a, b = idx[k], idx[k + 1]
            frames.append(Frame(
                t_start_s=edges[k] * 1e-9, t_end_s=edges[k + 1] * 1e-9,
                xyz=xyz[a:b], t_ns=t[a:b], reflectivity=None if refl is None else refl[a:b]))
        rest = idx[-1]
        self._buf_xyz = [xyz[rest:]]
        self._buf_t = [t[rest:]]
        self._buf_r = [refl[rest:]] if refl is not None else []
        self._next_start_ns = int(edges[-1])
        return frames


def strip_no_return(frame: Frame) -> Frame:
    """The frame without Livox "no return" points (0, 0, 0).  Drivers keep them on the wire so that
    time keeps moving while the lidar sees only sky (frames still come every period), then strip
    them here before detection and recording."""
    if not frame.n_points:
        return frame
    x = frame.xyz
    ret = (x[:, 0] != 0.0) | (x[:, 1] != 0.0) | (x[:, 2] != 0.0)    # column by column: any(axis=1) is 4x slower
    if ret.all():
        return frame
    return Frame(frame.t_start_s, frame.t_end_s, frame.xyz[ret], frame.t_ns[ret],
                 None if frame.reflectivity is None else frame.reflectivity[ret])
