"""Times and frames common to every reader: a file name's time read exactly, and a frame made
from one scan's points.

A scan with one stamp (a file named by its time, a ROS message's ``header.stamp``) becomes the
frame ``[stamp, stamp + 1/rate_hz)``: a Livox driver stamps a frame at its first point.  Points
without a time of their own are given the stamp, so Algorithm 1's detection time (the median
point time, :mod:`foveatrack.detection`) is the stamp.  Each reader yields ``(arrival_s, frame)``:
a bag's log time, for files the frame's end (when the sensor had finished the scan).

A file named by its time: ``<seconds>.<fraction>`` (up to 9 digits after the point) is seconds since
1970; a name of digits only is read in the unit its length gives, the one a time since 1970 has in
it: up to 10 digits seconds, 11-13 milliseconds, 14-16 microseconds, 17-19
nanoseconds (``1717243800005000`` is µs).  One folder's names must all be in one unit, and lie
before 2262 (what int64 ns hold).
"""

from __future__ import annotations

import re
import sys
from typing import NamedTuple

import numpy as np

from foveatrack.errors import UserError
from foveatrack.frames import Frame

_STEM = re.compile(r"^(\d+)(?:\.(\d{1,9}))?$")
_INT64_MAX = 2**63 - 1
# a name of digits only: (most digits, unit, ns per unit)
_INTEGER_UNITS = ((10, "s", 1_000_000_000), (13, "ms", 1_000_000), (16, "µs", 1_000), (19, "ns", 1))


class StampedFrame(NamedTuple):
    arrival_s: float
    frame: Frame


def ns_from_file_stem(stem: str) -> int | None:
    """``"1706255621.614239"`` -> 1706255621614239000: decimal seconds to integer ns exactly
    (through a float the last digits would round); ``"1717243800005000"`` (digits only, 16 of
    them: µs) -> 1717243800005000000; None if the name is not a time."""
    got = time_from_file_stem(stem)
    return None if got is None else got[0]


def time_from_file_stem(stem: str) -> tuple[int, str] | None:
    """``(ns, unit)`` of a file name's time, ``unit`` the one it was read in ("s", "ms", "µs",
    "ns"; a fraction is always seconds); None if the name is not a time or lies past 2262
    (what int64 ns hold)."""
    m = _STEM.match(stem)
    if m is None:
        return None
    digits, frac = m.group(1), m.group(2)
    if frac is not None:
        ns, unit = int(digits) * 1_000_000_000 + int(frac.ljust(9, "0")), "s"
    else:
        scale = next(((u, k) for most, u, k in _INTEGER_UNITS if len(digits) <= most), None)
        if scale is None:
            return None
        unit, ns = scale[0], int(digits) * scale[1]
    return (ns, unit) if ns <= _INT64_MAX else None


def warn_stderr(line: str) -> None:
    """Where a reader says what it read with a loss (its ``warn`` unless given): a line on stderr."""
    print(f"WARNING: {line}", file=sys.stderr, flush=True)


def cut_short(path, held: int, said: int) -> str:
    """What a reader says of a scan file cut short (its writer killed, a copy interrupted), whose whole
    points it read: the PCD and the .npy folders alike."""
    return (f"{path}: holds {held} of the {said} points its header gives (the file is cut short); "
            f"the rest of that scan is missing")


def seconds(ns) -> float:
    """``ns`` nanoseconds as the float nearest to the exact seconds: an integer quotient, rounded once
    (``ns * 1e-9`` rounds twice: a scan named ``1706255621.100000`` became 1706255621.1000001 s)."""
    return int(ns) / 1_000_000_000


def period_ns(rate_hz: float) -> int:
    return int(round(1e9 / rate_hz))


def frame_from_cloud(stamp_ns: int, xyz: np.ndarray, rate_hz: float, t_ns: np.ndarray | None = None,
                     reflectivity: np.ndarray | None = None) -> Frame:
    """The frame of one scan stamped ``stamp_ns``: valid points only (finite, not the (0, 0, 0)
    padding / no-return marker), each at its own time ``t_ns`` or at the stamp."""
    from foveatrack.detection import valid_points

    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    keep = valid_points(xyz)
    xyz = xyz[keep]
    if t_ns is None:
        t = np.full(xyz.shape[0], stamp_ns, dtype=np.int64)
    else:
        t = np.asarray(t_ns, dtype=np.int64).reshape(-1)[keep]
    refl = None if reflectivity is None else np.asarray(reflectivity).reshape(-1)[keep]
    t_end_ns = stamp_ns + period_ns(rate_hz)
    if t.size:
        t_end_ns = max(t_end_ns, int(t.max()) + 1)
    return Frame(seconds(stamp_ns), seconds(t_end_ns), xyz, t, refl)


def check_rate(rate_hz: float) -> float:
    if not (rate_hz > 0 and np.isfinite(rate_hz)):
        raise UserError(f"--rate-hz {rate_hz!r}: the frame rate must be a positive number")
    return float(rate_hz)
