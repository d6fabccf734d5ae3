"""Algorithm 2 of the paper (Appendix D.3): dead-band proportional speed control, and the neutral
command the tracker emits.

Sign conventions (written once here; tested in tests/tracker/test_control_and_table.py)
---------------------------------------------------------------------------------------
* Lidar frame: X forward (optical axis), Y left, Z up.
* Bearing errors: ``e_pan = atan2(y, x)`` (target to the left is positive),
  ``e_tilt = atan2(z, hypot(x, y))`` (target up is positive).  The paper writes
  ``e_y = arctan(y_m/x_m)``, ``e_p = arctan(z_m/x_m)``; atan2 keeps the quadrant (targets behind the
  sensor) and has no division by x -> 0 (straight overhead gives e_tilt = +90, e_pan = 0).
* Head: pan angle increases when turning LEFT (CCW from above); tilt increases UP.  So a target at
  positive azimuth needs ``pan_dir = +1`` (Pelco "left", cmd2 bit 0x04) and a target at positive
  elevation ``tilt_dir = +1`` (Pelco "up", 0x08).  The paper's ``v = -k e`` has the opposite sign
  only because of its gimbal's axis convention; here ``v = +k e``.
* Exactly behind (azimuth +-180) the tracker turns left (azimuths are wrapped to (-180, 180]).

Dead band (paper: "If the relative position is below a threshold (e.g. 2 deg), no action"):

.. math:: v = 0 \\text{ if } |e| < e_{db}, \\qquad v = k\\,e \\text{ otherwise}

so an error exactly on the edge moves the head.  ``|v|`` is then saturated to the axis's maximum
speed and converted to a Pelco-D speed byte with :meth:`AxisTable.byte_for_speed`.

Head-frame errors (``error_frame = "head"``): with the lidar on the tilt stage, pan turns about the
world vertical, so near the zenith the lidar-frame azimuth understates the pan needed by cos(tilt).
Given the tracker's tilt estimate, the point is turned into the pan frame,
``q = R_y(-tilt) (p + o)`` (o = lidar offset from the head centre), and
``e_pan = atan2(q_y, q_x)``, ``e_tilt = atan2(q_z, hypot(q_x, q_y)) - tilt``.  At tilt 0 and o = 0
this equals the paper's lidar-frame errors.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from foveatrack.detection import bearing_deg, wrap_deg
from foveatrack.speed_table import TURBO, AxisTable


@dataclass(frozen=True)
class HeadCommand:
    """A neutral speed command for both axes (drivers encode it as Pelco-D/P bytes).

    pan_dir : -1, 0, +1   +1 = turn LEFT (pan angle increases), -1 = right, 0 = stop
    pan_byte : 0..63 or 0xFF (turbo)
    tilt_dir : -1, 0, +1  +1 = UP (tilt increases), -1 = down, 0 = stop
    tilt_byte : 0..63
    A stopped axis has byte 0.
    """

    pan_dir: int = 0
    pan_byte: int = 0
    tilt_dir: int = 0
    tilt_byte: int = 0

    def __post_init__(self) -> None:
        if self.pan_dir not in (-1, 0, 1) or self.tilt_dir not in (-1, 0, 1):
            raise ValueError(f"directions must be -1, 0 or +1: {self}")
        if not (0 <= self.pan_byte <= 0x3F or self.pan_byte == TURBO) or not 0 <= self.tilt_byte <= 0x3F:
            raise ValueError(f"speed bytes out of range: {self}")
        if (self.pan_dir == 0 and self.pan_byte) or (self.tilt_dir == 0 and self.tilt_byte):
            raise ValueError(f"a stopped axis must have byte 0: {self}")

    @property
    def is_stop(self) -> bool:
        return self.pan_dir == 0 and self.tilt_dir == 0

    def axis(self, name: str) -> tuple[int, int]:
        return (self.pan_dir, self.pan_byte) if name == "pan" else (self.tilt_dir, self.tilt_byte)


STOP = HeadCommand()

_COMMANDS: dict[tuple[int, int, int, int], HeadCommand] = {STOP.axis("pan") + STOP.axis("tilt"): STOP}


def head_command(pan_dir: int, pan_byte: int, tilt_dir: int, tilt_byte: int) -> HeadCommand:
    """``HeadCommand(pan_dir, pan_byte, tilt_dir, tilt_byte)``, one shared instance per value (it
    is immutable), so the per-frame path validates each distinct command once."""
    key = (pan_dir, pan_byte, tilt_dir, tilt_byte)
    cmd = _COMMANDS.get(key)
    if cmd is None:
        cmd = HeadCommand(pan_dir, pan_byte, tilt_dir, tilt_byte)
        _COMMANDS[key] = cmd
    return cmd


def lidar_errors_deg(p_lidar) -> tuple[float, float]:
    """The paper's bearing errors (atan2 form), lidar frame: (e_pan, e_tilt) [deg]."""
    return bearing_deg(*np.asarray(p_lidar, float).tolist())


def head_errors_deg(p_lidar, tilt_deg: float, lidar_offset_m=(0.0, 0.0, 0.0)) -> tuple[float, float]:
    """Pan and tilt changes [deg] that put the point on the optical axis (see module docstring)."""
    px, py, pz = np.asarray(p_lidar, float).tolist()
    ox, oy, oz = np.asarray(lidar_offset_m, float).tolist()
    q0, q1, q2 = px + ox, py + oy, pz + oz
    t = math.radians(tilt_deg)
    c, s = math.cos(t), math.sin(t)
    # R_y(-t) applied to q: x' = c x - s z, z' = s x + c z   (tilt up by t turns lidar +X toward +Z)
    qx, qy, qz = c * q0 - s * q2, q1, s * q0 + c * q2
    e_pan = wrap_deg(math.degrees(math.atan2(qy, qx)))
    e_tilt = math.degrees(math.atan2(qz, math.hypot(qx, qy))) - tilt_deg
    return e_pan, e_tilt


def deadband_p(error_deg: float, deadband_deg: float, gain_1_s: float) -> float:
    """Algorithm 2 lines 13-22: 0 inside the dead band (``|e| < db``), else ``gain * e`` [deg/s]."""
    if abs(error_deg) < deadband_deg:
        return 0.0
    return gain_1_s * error_deg


def limit_for_stops(v_deg_s: float, angle_deg: float, sigma_deg: float, lo_deg: float, hi_deg: float,
                    margin_deg: float, lookahead_s: float) -> tuple[float, bool]:
    """Reduce a speed so the estimated angle (plus 2 sigma) stays ``margin_deg`` inside the stops
    ``lookahead_s`` from now.  Returns (speed, limited?).  Never commands toward a stop it is at."""
    if v_deg_s > 0:
        room = hi_deg - margin_deg - (angle_deg + 2.0 * sigma_deg)
    elif v_deg_s < 0:
        room = (angle_deg - 2.0 * sigma_deg) - (lo_deg + margin_deg)
    else:
        return 0.0, False
    vmax = max(room, 0.0) / max(lookahead_s, 1e-9)
    if abs(v_deg_s) <= vmax:
        return v_deg_s, False
    return math.copysign(vmax, v_deg_s), True


def speed_to_axis(v_deg_s: float, table: AxisTable, *, max_speed_deg_s: float | None = None,
                  allow_turbo: bool = False, floor: bool = False) -> tuple[int, int, float]:
    """Signed speed -> (dir, byte, table speed of that byte [deg/s, signed]).

    ``|v|`` is first saturated to ``max_speed_deg_s`` (and the table's maximum).  ``floor=True``
    picks the fastest byte not faster than ``|v|`` (used when a stop limits the speed); if none, stop.
    """
    if v_deg_s == 0.0 or not math.isfinite(v_deg_s):
        return 0, 0, 0.0
    vmax = table.max_speed_deg_s(allow_turbo)
    if max_speed_deg_s is not None:
        vmax = min(vmax, max_speed_deg_s)
    mag = min(abs(v_deg_s), vmax)
    if floor:
        if mag < table.min_speed_deg_s():
            return 0, 0, 0.0
        speeds, _ = table.speeds_array()
        idx = np.arange(65 if allow_turbo else 64)
        s = speeds[idx]
        ok = np.isfinite(s) & (s > 0) & (s <= mag + 1e-12)
        k = idx[ok][np.argmax(s[ok])]
        byte = TURBO if k == 64 else int(k)
    else:
        byte = table.byte_for_speed(mag, allow_turbo=allow_turbo)
        if max_speed_deg_s is not None and table.speed_deg_s(byte) > max_speed_deg_s + 1e-12:
            return speed_to_axis(v_deg_s, table, max_speed_deg_s=max_speed_deg_s,
                                 allow_turbo=allow_turbo, floor=True)
    d = 1 if v_deg_s > 0 else -1
    return d, byte, d * table.speed_deg_s(byte)
