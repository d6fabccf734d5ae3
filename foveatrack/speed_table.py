"""The head's speed table: Pelco-D speed byte -> actual rotation speed, per axis (paper App. D.4).

"The calibration builds a lookup table mapping the command to actual rotation speed.  Then during the
actual intruder tracking, the rotation speed is determined from the command and then integrated to
produce the angle estimate."

Bytes: pan ``0x00..0x3F`` and ``0xFF`` (turbo: the device's fastest, *not* a step after 0x3F);
tilt ``0x00..0x3F``.  Speeds are magnitudes [deg/s], assumed equal in both directions of an axis
(the calibrator measures both directions and reports their asymmetry).

Interpolation: the table's *knots* are the entries with a finite speed (measured, or nominal).  A
byte between two knots gets the piecewise-linear interpolation in byte number (which is monotone
whenever the knots are, and never overshoots them); its uncertainty is the larger of its two
neighbours'.  A byte outside the knots' span has no known speed (NaN) and is never commanded.
Turbo is only known from its own entry.

Inverse (:meth:`AxisTable.byte_for_speed`): among the bytes with a known speed > 0, the one whose
speed is nearest to the request (ties -> the slower).  This works on non-monotone measured tables
(it bisects the candidates sorted by speed, not by byte number), and a request beyond the table
gets the fastest byte.

File (JSON)::

    {"format": "foveatrack-speed-table", "version": 1, "unit": "deg/s",
     "date": "2025-01-01T12:00:00Z", "head": "PTS-303H", "source": "calibration ...",
     "dead_time_s": 0.05, "accel_deg_s2": null,
     "axes": {"pan":  {"entries": [{"byte": 0, "speed": 0.0, "sigma": 0.01, "measured": true}, ...]},
              "tilt": {"entries": [...]}}}

``unit`` may be ``"deg/s"`` or ``"rad/s"`` (the speeds converted to deg/s on load; the ``accel_deg_s2``
keys are in deg/s^2 whatever the unit, as their name says).  ``byte`` may be an
integer or a string such as ``"0x3F"``/``"turbo"``.
"""

from __future__ import annotations

import bisect
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from foveatrack.errors import UserError
from gimbal.head_facts import TURBO as HEAD_TURBO

TURBO = HEAD_TURBO   # 0xFF, declared once with the head's facts
AXES = ("pan", "tilt")
#: The most bytes in a row a table is trusted to interpolate between two known speeds: the default
#: calibration plan's widest (40, 48, 56 leave 7 between).  With known speeds only at 4, 8, 16, 32, 63
#: the bytes the tracker uses were several percent off and a 60 s reconstruction drifted 3.6 % of
#: range (docs/tracker.md).
MAX_INTERPOLATED_RUN = 7
UNITS = {"deg/s": 1.0, "rad/s": 180.0 / math.pi}
FORMAT = "foveatrack-speed-table"


def axis_bytes(axis: str) -> tuple[int, ...]:
    """The speed bytes an axis accepts: 0..63, plus turbo 0xFF for pan."""
    return tuple(range(64)) + ((TURBO,) if axis == "pan" else ())


def byte_ranges(bs) -> str:
    """Speed bytes in words: [0, 1, 2, 5, 7, 8] -> '0-2, 5, 7-8' (turbo as 'turbo')."""
    bs = sorted(bs)
    parts, i = [], 0
    while i < len(bs):
        j = i
        while j + 1 < len(bs) and bs[j + 1] == bs[j] + 1 and bs[j + 1] != TURBO:
            j += 1
        name = lambda b: "turbo" if b == TURBO else str(b)  # noqa: E731
        parts.append(name(bs[i]) if i == j else f"{name(bs[i])}-{name(bs[j])}")
        i = j + 1
    return ", ".join(parts)


@dataclass(frozen=True)
class SpeedEntry:
    """One table entry.  ``speed_deg_s`` NaN = unknown; ``measured`` False = not measured
    (nominal, interpolated or failed); ``delay_s`` = effective start delay seen when measuring."""

    byte: int
    speed_deg_s: float
    sigma_deg_s: float
    measured: bool = True
    delay_s: float | None = None
    note: str = ""


@dataclass(frozen=True)
class AxisTable:
    """One axis's entries; ``accel_deg_s2`` (optional) overrides the table-wide acceleration for
    this axis (heads accelerate their two axes differently)."""

    axis: str
    entries: tuple[SpeedEntry, ...]
    accel_deg_s2: float | None = None
    _speed: np.ndarray = field(init=False, repr=False, compare=False)   # over bytes 0..64 (64 = turbo)
    _sigma: np.ndarray = field(init=False, repr=False, compare=False)
    # Per-frame lookups as plain Python (see :meth:`_build_lookups`): speeds by index, and per
    # allow_turbo the candidates sorted by speed for :meth:`byte_for_speed`.
    _speed_list: list = field(init=False, repr=False, compare=False)
    _lookup: dict = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.axis not in AXES:
            raise ValueError(f"axis must be one of {AXES}")
        seen = set()
        for e in self.entries:
            if e.byte not in axis_bytes(self.axis):
                raise UserError(f"{self.axis}: speed byte {e.byte!r} is not allowed "
                                f"(0..63{' or 0xFF turbo' if self.axis == 'pan' else ''})")
            if e.byte in seen:
                raise UserError(f"{self.axis}: speed byte {e.byte} is listed twice")
            seen.add(e.byte)
            # as from_dict checks a file: a speed is a magnitude (the direction is the command's)
            if e.speed_deg_s < 0:
                raise UserError(f"{self.axis}: speed byte {e.byte}: speed must be >= 0 (a magnitude), "
                                f"got {e.speed_deg_s}")
            if e.sigma_deg_s < 0:
                raise UserError(f"{self.axis}: speed byte {e.byte}: sigma must be >= 0, got {e.sigma_deg_s}")
        speed = np.full(65, np.nan)
        sigma = np.full(65, np.nan)
        knots = sorted((e for e in self.entries if math.isfinite(e.speed_deg_s) and e.byte != TURBO),
                       key=lambda e: e.byte)
        if knots:
            kb = np.array([e.byte for e in knots], float)
            ks = np.array([e.speed_deg_s for e in knots])
            kg = np.array([e.sigma_deg_s if math.isfinite(e.sigma_deg_s) else abs(e.speed_deg_s) for e in knots])
            b = np.arange(64, dtype=float)
            inside = (b >= kb[0]) & (b <= kb[-1])
            speed[:64][inside] = np.interp(b[inside], kb, ks)
            # sigma: the larger of the two neighbouring knots (exact at the knots)
            j = np.clip(np.searchsorted(kb, b[inside], side="left"), 0, len(kb) - 1)
            i = np.clip(j - 1, 0, len(kb) - 1)
            at_knot = kb[j] == b[inside]
            sigma[:64][inside] = np.where(at_knot, kg[j], np.maximum(kg[i], kg[j]))
        for e in self.entries:
            if e.byte == TURBO and math.isfinite(e.speed_deg_s):
                speed[64] = e.speed_deg_s
                sigma[64] = e.sigma_deg_s if math.isfinite(e.sigma_deg_s) else abs(e.speed_deg_s)
        object.__setattr__(self, "_speed", speed)
        object.__setattr__(self, "_sigma", sigma)
        self._build_lookups()

    def _build_lookups(self) -> None:
        """Precompute what the tracker asks every frame (the same values as the numpy routes):
        ``speed_deg_s`` as a list, and per ``allow_turbo`` the max / min candidate speed and the
        candidates sorted by (speed, candidate position) for the bisection in :meth:`byte_for_speed`."""
        object.__setattr__(self, "_speed_list", [float(v) for v in self._speed])
        lookup = {}
        for turbo in (False, True):
            b, s = self._candidates(turbo)
            bl, sl = [int(v) for v in b], [float(v) for v in s]
            order = sorted(range(len(sl)), key=lambda i: (sl[i], i))
            lookup[turbo] = (float(s.max()) if s.size else 0.0, float(s.min()) if s.size else 0.0,
                             [sl[i] for i in order], [bl[i] for i in order])
        object.__setattr__(self, "_lookup", lookup)

    @staticmethod
    def _idx(byte: int) -> int:
        return 64 if byte == TURBO else int(byte)

    def speed_deg_s(self, byte: int) -> float:
        """Speed magnitude [deg/s] of a byte (NaN if unknown)."""
        return self._speed_list[64 if byte == TURBO else int(byte)]

    def sigma_deg_s(self, byte: int) -> float:
        return float(self._sigma[self._idx(byte)])

    def entry(self, byte: int) -> SpeedEntry | None:
        for e in self.entries:
            if e.byte == byte:
                return e
        return None

    def is_measured(self, byte: int) -> bool:
        e = self.entry(byte)
        return bool(e is not None and e.measured and math.isfinite(e.speed_deg_s))

    @property
    def unmeasured_bytes(self) -> tuple[int, ...]:
        return tuple(b for b in axis_bytes(self.axis) if not self.is_measured(b))

    def _candidates(self, allow_turbo: bool) -> tuple[np.ndarray, np.ndarray]:
        idx = np.arange(65 if allow_turbo else 64)
        s = self._speed[idx]
        ok = np.isfinite(s) & (s > 0)
        bytes_ = np.where(idx == 64, TURBO, idx)
        return bytes_[ok], s[ok]

    def max_speed_deg_s(self, allow_turbo: bool = False) -> float:
        return self._lookup[bool(allow_turbo)][0]

    def min_speed_deg_s(self) -> float:
        return self._lookup[False][1]

    def byte_for_speed(self, speed_deg_s: float, allow_turbo: bool = False) -> int:
        """Inverse: the byte whose known speed (> 0) is nearest to ``|speed_deg_s|`` (ties: slower).

        Bisection in the candidates sorted by (speed, byte order): ``|s - target|`` only grows
        away from the target on either side, so the nearest speed is a neighbour of the insertion
        point, and the slowest speed within 1e-12 of the nearest distance is found by walking down
        from there.  The same byte as :meth:`_byte_for_speed_scan` (tested), in ~1 us instead of ~20.
        """
        smax, _, ss, bs = self._lookup[bool(allow_turbo)]
        target = abs(float(speed_deg_s))
        if not ss or target != target:   # no candidate, or NaN: the scan raises its error
            return self._byte_for_speed_scan(speed_deg_s, allow_turbo)
        target = min(target, smax)
        j = bisect.bisect_left(ss, target)   # ss[j - 1] < target <= ss[j]
        n = len(ss)
        d_lo = abs(ss[j - 1] - target) if j > 0 else math.inf
        d_hi = abs(ss[j] - target) if j < n else math.inf
        thr = min(d_lo, d_hi) + 1e-12
        i = j - 1
        if i >= 0 and d_lo <= thr:
            while i > 0 and abs(ss[i - 1] - target) <= thr:
                i -= 1
            # among equal speeds the first in byte order (sorted so), as the scan's argmin
            return bs[i]
        return bs[j]

    def _byte_for_speed_scan(self, speed_deg_s: float, allow_turbo: bool = False) -> int:
        """The general route of :meth:`byte_for_speed`: scan every candidate (numpy)."""
        b, s = self._candidates(allow_turbo)
        if b.size == 0:
            raise UserError(f"speed table: the {self.axis} axis has no byte with a known speed > 0")
        target = min(abs(float(speed_deg_s)), float(s.max()))  # beyond the table: the fastest (|s - 1e17| ties)
        d = np.abs(s - target)
        best = np.flatnonzero(d <= d.min() + 1e-12)
        k = best[np.argmin(s[best])]
        return int(b[k])

    def speeds_array(self) -> tuple[np.ndarray, np.ndarray]:
        """(speed, sigma) over bytes 0..63 and turbo at index 64 [deg/s]; NaN = unknown."""
        return self._speed.copy(), self._sigma.copy()

    def problems(self, max_byte: int = 63) -> list[str]:
        """What in this axis's speeds the tracker runs with but steers wrong by, each in words naming
        the bytes at fault (empty: none).  Such a table is not refused (the inverse works on any
        table with a speed > 0); it is said.

        ``max_byte``: the highest byte the head may be sent (a config's ``[head] max_pan_byte`` /
        ``max_tilt_byte``; 63 where there is no limit).  Bytes above it are never sent whatever the
        table says, so their missing speeds are nobody's problem: ``calibrate --config`` measures none
        of them (its plan drops them), and the table it writes was said to lack them at every start.

        * Speeds that fall as the byte rises: a known speed below that of a lower byte by more than
          3 sigma of the two (a measured table's slow bytes scatter about 0 within their sigmas;
          an entry without a sigma counts 0), and a turbo slower than the fastest byte (turbo is the
          device's fastest).  The tracker picks the byte of the nearest speed and interpolates
          between known ones, so around such bytes it turns at speeds the head does not have.
        * Bytes above the highest known speed, up to ``max_byte``: they have none and are never sent,
          so the tracker's fastest turn is less than the head's.  Below the lowest, only more than
          ``MAX_INTERPOLATED_RUN`` of them (the slowest turn is then far from a stop; the bytes under a
          table starting at 4 barely move a PTS-303H).
        * More than ``MAX_INTERPOLATED_RUN`` bytes in a row (up to ``max_byte``) between two known
          speeds: interpolated.
        """
        if not 0 <= max_byte <= 63:
            raise ValueError(f"max_byte must be 0..63, got {max_byte}")
        out = []
        knots = sorted((e for e in self.entries if math.isfinite(e.speed_deg_s) and e.byte != TURBO),
                       key=lambda e: e.byte)
        sig = lambda e: e.sigma_deg_s if math.isfinite(e.sigma_deg_s) else 0.0  # noqa: E731
        falls, top = [], None
        for e in knots:
            if top is not None and e.speed_deg_s < top.speed_deg_s - 3.0 * math.hypot(sig(e), sig(top)) - 1e-9:
                falls.append(f"byte {e.byte} ({e.speed_deg_s:.4g} deg/s) is slower than byte {top.byte} "
                             f"({top.speed_deg_s:.4g})")
            if top is None or e.speed_deg_s > top.speed_deg_s:
                top = e
        turbo = self.entry(TURBO)
        if (turbo is not None and math.isfinite(turbo.speed_deg_s) and top is not None
                and turbo.speed_deg_s < top.speed_deg_s - 3.0 * math.hypot(sig(turbo), sig(top)) - 1e-9):
            falls.append(f"turbo ({turbo.speed_deg_s:.4g} deg/s) is slower than byte {top.byte} ({top.speed_deg_s:.4g})")
        if falls:
            shown = "; ".join(falls[:6]) + (f"; and {len(falls) - 6} more" if len(falls) > 6 else "")
            out.append(f"{self.axis} speeds fall as the speed byte rises: {shown}.  The tracker picks the byte "
                       "of the nearest speed and interpolates between bytes, so near these it turns at speeds "
                       "the head does not have: check these entries, or measure the table again "
                       "(foveatrack calibrate)")
        if not knots:
            out.append(f"{self.axis} bytes 0-63 have no speed: none is ever sent"
                       + (" (turbo only)" if self.axis == "pan" else ""))
            return out
        lo, hi = knots[0].byte, knots[-1].byte
        if lo > MAX_INTERPOLATED_RUN:
            out.append(f"{self.axis} bytes {byte_ranges(range(lo))} have no speed (the lowest listed is {lo}): "
                       f"they are never sent, and the slowest {self.axis} turn is byte {lo}'s "
                       f"{knots[0].speed_deg_s:.4g} deg/s")
        if hi < max_byte:
            limit = "" if max_byte == 63 else f", the highest the head may be sent {max_byte}"
            out.append(f"{self.axis} bytes {byte_ranges(range(hi + 1, max_byte + 1))} have no speed (the highest "
                       f"listed is {hi}{limit}): they are never sent, and the fastest {self.axis} turn is "
                       f"{self.max_speed_deg_s(False):.4g} deg/s" + (" without turbo" if self.axis == "pan" else ""))
        # a run of interpolated bytes counts only as far as the bytes that may be sent
        gaps = [(a.byte, b.byte) for a, b in zip(knots, knots[1:])
                if min(b.byte, max_byte + 1) - a.byte - 1 > MAX_INTERPOLATED_RUN]
        if gaps:
            said = ", ".join(f"{byte_ranges(range(a + 1, b))} (between {a} and {b})" for a, b in gaps)
            out.append(f"{self.axis} speeds are interpolated over more than {MAX_INTERPOLATED_RUN} bytes in a row: "
                       f"{said}: the speeds there are interpolated guesses; measure at least every "
                       f"{MAX_INTERPOLATED_RUN + 1}th byte (a table known only at 4, 8, 16, 32 and 63 once steered "
                       "the tracker several percent off)")
        return out


@dataclass(frozen=True)
class SpeedTable:
    """Both axes' tables plus the head timing the reconstruction needs.

    dead_time_s : float >= 0 [s]   command-to-motion delay of the head (after the bytes arrived)
    accel_deg_s2 : float > 0 or None [deg/s^2]  acceleration limit (None: speed changes at once)
    """

    pan: AxisTable
    tilt: AxisTable
    unit: str = "deg/s"
    date: str = ""
    head: str = ""
    source: str = ""
    dead_time_s: float = 0.0
    accel_deg_s2: float | None = None

    def axis(self, name: str) -> AxisTable:
        if name == "pan":
            return self.pan
        if name == "tilt":
            return self.tilt
        raise ValueError(f"axis must be 'pan' or 'tilt', got {name!r}")

    def axis_accel_deg_s2(self, name: str) -> float | None:
        """The acceleration of axis ``name``: its own where the table has one, else the table-wide one
        (heads accelerate their two axes differently)."""
        return self.axis(name).accel_deg_s2 or self.accel_deg_s2

    @property
    def unmeasured(self) -> dict[str, tuple[int, ...]]:
        return {a: self.axis(a).unmeasured_bytes for a in AXES}

    def problems(self, max_byte: dict[str, int] | None = None) -> list[str]:
        """Both axes' :meth:`AxisTable.problems`: what a user who supplies this table must hear.

        ``max_byte``: ``{"pan": .., "tilt": ..}``, the highest byte each axis may be sent (a daemon
        config's ``[head]`` limits); missing (a scene's table): 63, every byte."""
        lim = max_byte or {}
        return self.pan.problems(lim.get("pan", 63)) + self.tilt.problems(lim.get("tilt", 63))

    # ---- defaults ------------------------------------------------------------------------------
    @classmethod
    def nominal(cls, pan_max_deg_s: float = 15.0, tilt_max_deg_s: float = 2.0,
                pan_turbo_deg_s: float | None = 20.0, rel_sigma: float = 0.3) -> "SpeedTable":
        """A documented table for an *uncalibrated* head: linear ``(b + 1) / 64 * max`` (the facts
        file's FLIR D300E rule ``(p + 1) / 65 * max`` rescaled so that 0x3F gives the maximum), pan
        15 deg/s and tilt 2 deg/s at 0x3F (the PTS family datasheet figures), turbo 20 deg/s (a
        guess), every entry ``measured = False`` with 30 % uncertainty.  Good enough to start
        tracking; calibrate before trusting reconstruction."""
        def axis(name, vmax, turbo):
            es = [SpeedEntry(b, (b + 1) / 64.0 * vmax, rel_sigma * (b + 1) / 64.0 * vmax, False, note="nominal")
                  for b in range(64)]
            if turbo is not None:
                es.append(SpeedEntry(TURBO, turbo, rel_sigma * turbo, False, note="nominal"))
            return AxisTable(name, tuple(es))
        return cls(axis("pan", pan_max_deg_s, pan_turbo_deg_s), axis("tilt", tilt_max_deg_s, None),
                   date="", head="nominal", source="SpeedTable.nominal(): uncalibrated, linear (b+1)/64*max")

    # ---- files -------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        def ent(e: SpeedEntry) -> dict:
            d = {"byte": "turbo" if e.byte == TURBO else e.byte,
                 "speed": None if not math.isfinite(e.speed_deg_s) else e.speed_deg_s,
                 "sigma": None if not math.isfinite(e.sigma_deg_s) else e.sigma_deg_s,
                 "measured": bool(e.measured)}
            if e.delay_s is not None:
                d["delay_s"] = e.delay_s
            if e.note:
                d["note"] = e.note
            return d
        return {"format": FORMAT, "version": 1, "unit": "deg/s", "date": self.date, "head": self.head,
                "source": self.source, "dead_time_s": self.dead_time_s, "accel_deg_s2": self.accel_deg_s2,
                "axes": {a: {"entries": [ent(e) for e in self.axis(a).entries],
                             **({"accel_deg_s2": self.axis(a).accel_deg_s2} if self.axis(a).accel_deg_s2 else {})}
                         for a in AXES}}

    def save(self, path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=1) + "\n")

    @classmethod
    def load(cls, path) -> "SpeedTable":
        p = Path(path)
        from foveatrack.config_util import read_small_text

        try:
            text = read_small_text(p, "speed table")    # not /dev/zero (3.5 GB, then MemoryError)
        except OSError as exc:
            raise UserError(f"speed table {p}: cannot read ({exc.strerror or exc})") from None
        except UnicodeDecodeError:
            raise UserError(f"speed table {p}: not a text file") from None
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise UserError(f"speed table {p}: not valid JSON (line {exc.lineno}: {exc.msg})") from None
        except RecursionError:
            raise UserError(f"speed table {p}: arrays or objects nested too deep") from None
        return cls.from_dict(data, where=f"speed table {p}")

    @classmethod
    def from_dict(cls, data, where: str = "speed table") -> "SpeedTable":
        if not isinstance(data, dict):
            raise UserError(f"{where}: expected a JSON object at the top level")
        allowed = {"format", "version", "unit", "date", "head", "source", "dead_time_s", "accel_deg_s2", "axes"}
        unknown = sorted(set(data) - allowed)
        if unknown:
            raise UserError(f"{where}: unknown key(s) {unknown}; allowed: {sorted(allowed)}")
        if data.get("format") != FORMAT:
            raise UserError(f"{where}: format must be {FORMAT!r}, got {data.get('format')!r}")
        if data.get("version") != 1:
            raise UserError(f"{where}: version must be 1, got {data.get('version')!r}")
        unit = data.get("unit", "deg/s")
        if unit not in UNITS:
            raise UserError(f"{where}: unit must be one of {list(UNITS)}, got {unit!r}")
        k = UNITS[unit]
        axes = data.get("axes")
        if not isinstance(axes, dict) or set(axes) != set(AXES):
            raise UserError(f"{where}: axes must be an object with exactly the keys 'pan' and 'tilt'")
        tables = {}
        for a in AXES:
            ax = axes[a]
            if not isinstance(ax, dict) or not isinstance(ax.get("entries"), list) or set(ax) - {"entries", "accel_deg_s2"}:
                raise UserError(f"{where}: axes.{a} must be {{\"entries\": [...], \"accel_deg_s2\": optional}}")
            ax_acc = ax.get("accel_deg_s2")
            if ax_acc is not None:
                # named in deg/s^2 whatever ``unit`` says (the speeds'): not scaled (a rad/s table's
                # 40.5 deg/s^2 once loaded as 2322)
                ax_acc = _num_or_nan(ax_acc, f"{where}: axes.{a}.accel_deg_s2")
                if not (math.isfinite(ax_acc) and ax_acc > 0):
                    raise UserError(f"{where}: axes.{a}.accel_deg_s2 must be a number > 0 or absent")
            entries = []
            for i, e in enumerate(ax["entries"]):
                w = f"{where}: axes.{a}.entries[{i}]"
                if not isinstance(e, dict):
                    raise UserError(f"{w} must be an object")
                bad = sorted(set(e) - {"byte", "speed", "sigma", "measured", "delay_s", "note"})
                if bad:
                    raise UserError(f"{w}: unknown key(s) {bad}; allowed: byte, speed, sigma, measured, delay_s, note")
                b = _parse_byte(e.get("byte"), w, a)
                sp = _num_or_nan(e.get("speed"), w + ".speed")
                sg = _num_or_nan(e.get("sigma"), w + ".sigma")
                if math.isfinite(sp) and sp < 0:
                    raise UserError(f"{w}.speed must be >= 0 (a magnitude), got {sp}")
                if math.isfinite(sg) and sg < 0:
                    raise UserError(f"{w}.sigma must be >= 0, got {sg}")
                meas = e.get("measured", True)
                if not isinstance(meas, bool):
                    raise UserError(f"{w}.measured must be true or false")
                dl = e.get("delay_s")
                if dl is not None:
                    dl = _num_or_nan(dl, w + ".delay_s")
                entries.append(SpeedEntry(b, sp * k, sg * k, meas, dl, str(e.get("note", ""))))
            try:
                tables[a] = AxisTable(a, tuple(entries), ax_acc)
            except UserError as exc:  # its own checks (a byte listed twice) name no file
                raise UserError(f"{where}: axes.{exc}") from None
            if tables[a].max_speed_deg_s(allow_turbo=True) <= 0:
                raise UserError(f"{where}: axes.{a} has no entry with a known speed > 0; it cannot be used")
        dt = _num_or_nan(data.get("dead_time_s", 0.0), where + ": dead_time_s")
        if not (math.isfinite(dt) and dt >= 0):
            raise UserError(f"{where}: dead_time_s must be a number >= 0")
        acc = data.get("accel_deg_s2")
        if acc is not None:
            acc = _num_or_nan(acc, where + ": accel_deg_s2")     # deg/s^2 by its name, as above
            if not (math.isfinite(acc) and acc > 0):
                raise UserError(f"{where}: accel_deg_s2 must be a number > 0 or null")
        return cls(tables["pan"], tables["tilt"], unit="deg/s", date=str(data.get("date", "")),
                   head=str(data.get("head", "")), source=str(data.get("source", "")),
                   dead_time_s=dt, accel_deg_s2=acc)


def _parse_byte(v, where: str, axis: str) -> int:
    if isinstance(v, str):
        s = v.strip().lower()
        if s == "turbo":
            s = str(TURBO)
        try:
            v = int(s, 0)
        except ValueError:
            raise UserError(f"{where}.byte must be 0..63, '0x3F' style or 'turbo', got {v!r}") from None
    if isinstance(v, bool) or not isinstance(v, int) or v not in axis_bytes(axis):
        raise UserError(f"{where}.byte must be 0..63{' or turbo' if axis == 'pan' else ''}, got {v!r}")
    return v


def _num_or_nan(v, where: str) -> float:
    if v is None:
        return float("nan")
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise UserError(f"{where} must be a number or null, got {v!r}")
    return float(v)
