"""The PTS-303H model's parameters, its families, its state record and each unit's speed curve
(see :mod:`gimbal.pts303h`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from gimbal.errors import GimbalError
from gimbal.head_facts import PTS303_TILT_STOPS_DEG
from gimbal.pelco import MAX_SPEED_BYTE, PAN_TURBO


FEEDBACK_MODES = ("none", "at-rest", "always")
_BYTE = [bytes((b,)) for b in range(256)]
AXES = ("pan", "tilt")


@dataclass(frozen=True)
class HeadParams:
    """Parameters of a head family (nominal values; a unit seed perturbs some of them).

    Defaults are the PTS-303 family as far as the facts go: pan 0-15 deg/s and tilt 0-2 deg/s
    from a family member's listing; accelerations, dead time, ripple and quirks are assumptions
    typical of worm-gear heads.  See :data:`HEAD_FAMILIES` for a faster heavy head.

    pan_speed_max_deg_s : float > 0 [deg/s], nominal pan speed at byte 0x3F
    pan_turbo_deg_s : float > pan_speed_max_deg_s [deg/s], nominal turbo (byte 0xFF) pan speed
    tilt_speed_max_deg_s : float > 0 [deg/s], nominal tilt speed at byte 0x3F (no tilt turbo)
    pan_accel_deg_s2, tilt_accel_deg_s2 : float > 0 [deg/s^2], |acceleration| while changing speed
    dead_time_s : float >= 0 [s], from a frame's last byte to the start of its effect
    dead_zone_byte : int 0-62, nominal last byte giving zero speed (unit: +-1)
    curve_gamma : float > 0, nominal exponent of the speed curve
    unit_gain_spread : float >= 0, relative std of a unit's gain
    unit_gamma_spread : float >= 0, log-std of a unit's exponent
    unit_step_spread : float >= 0, log-std of the per-byte speed increments
    ripple_rel : float in [0, 0.5), relative speed ripple amplitude
    ripple_freq_hz : float > 0 [Hz], nominal ripple frequency (unit: +-10 %)
    tilt_min_deg, tilt_max_deg : [deg], the tilt stop brackets (tilt positive = up)
    abs_set_quiet_s : float >= 0 [s], line-quiet time an absolute set needs (0 = always obeyed)
    reply_delay_s : float >= 0 [s], turnaround from a query's last byte to the reply
    tilt_zero : 'zenith' (family quirk: native tilt word 0 = zenith) or 'level'
    garbage_margin_deg : float > 0 [deg], garbage replies are at least this far from the truth
    history_s : float > 0 [s], how far back :meth:`PTS303H.angles_at` can answer
    """

    family: str = "pts-303"
    pan_speed_max_deg_s: float = 15.0
    pan_turbo_deg_s: float = 20.0
    tilt_speed_max_deg_s: float = 2.0
    pan_accel_deg_s2: float = 40.0
    tilt_accel_deg_s2: float = 10.0
    dead_time_s: float = 0.04
    dead_zone_byte: int = 2
    curve_gamma: float = 1.5
    unit_gain_spread: float = 0.08
    unit_gamma_spread: float = 0.15
    unit_step_spread: float = 0.2
    ripple_rel: float = 0.02
    ripple_freq_hz: float = 1.5
    tilt_min_deg: float = PTS303_TILT_STOPS_DEG[0]
    tilt_max_deg: float = PTS303_TILT_STOPS_DEG[1]
    abs_set_quiet_s: float = 0.2
    reply_delay_s: float = 0.003
    tilt_zero: str = "zenith"
    garbage_margin_deg: float = 2.0
    history_s: float = 2.0

    def __post_init__(self) -> None:
        def bad(name: str, allowed: str) -> GimbalError:
            return GimbalError(
                f"head parameter {name}={getattr(self, name)!r} is not allowed; {allowed}"
            )

        for name in ("pan_speed_max_deg_s", "tilt_speed_max_deg_s", "pan_accel_deg_s2",
                     "tilt_accel_deg_s2", "curve_gamma", "ripple_freq_hz", "history_s",
                     "garbage_margin_deg"):
            if not getattr(self, name) > 0:
                raise bad(name, "must be > 0")
        for name in ("dead_time_s", "unit_gain_spread", "unit_gamma_spread", "unit_step_spread",
                     "abs_set_quiet_s", "reply_delay_s"):
            if not getattr(self, name) >= 0:
                raise bad(name, "must be >= 0")
        if not self.pan_turbo_deg_s > self.pan_speed_max_deg_s:
            raise bad("pan_turbo_deg_s", "must exceed pan_speed_max_deg_s")
        if not 0 <= self.ripple_rel < 0.5:
            raise bad("ripple_rel", "allowed 0 <= ripple_rel < 0.5")
        if not (isinstance(self.dead_zone_byte, int) and 0 <= self.dead_zone_byte <= 61):
            raise bad("dead_zone_byte", "allowed integers 0-61")
        if not self.tilt_min_deg < 0 < self.tilt_max_deg:
            raise bad("tilt_min_deg", "need tilt_min_deg < 0 < tilt_max_deg")
        if self.tilt_zero not in ("zenith", "level"):
            raise bad("tilt_zero", "use 'zenith' or 'level'")

    @classmethod
    def for_family(cls, name: str, **overrides) -> "HeadParams":
        """Parameters of a named family from :data:`HEAD_FAMILIES`, with field overrides."""
        if name not in HEAD_FAMILIES:
            raise GimbalError(f"unknown head family {name!r}; known: {', '.join(HEAD_FAMILIES)}")
        return replace(HEAD_FAMILIES[name], **overrides)


HEAD_FAMILIES: dict[str, HeadParams] = {
    # PTS-303 family listing: pan 0-15 deg/s, tilt 0-2 deg/s.
    "pts-303": HeadParams(),
    # A heavier worm-gear head of the BIT-PT850 class: pan 0.01-30 deg/s, tilt 0.01-15 deg/s.
    "heavy-worm": HeadParams(
        family="heavy-worm", pan_speed_max_deg_s=30.0, pan_turbo_deg_s=40.0,
        tilt_speed_max_deg_s=15.0, pan_accel_deg_s2=60.0, tilt_accel_deg_s2=40.0,
        dead_zone_byte=1, tilt_min_deg=-45.0, tilt_max_deg=75.0,
    ),
}


@dataclass(frozen=True)
class HeadState:
    """True head state at ``t_s`` (speeds include the ripple)."""

    t_s: float
    pan_deg: float
    tilt_deg: float
    pan_speed_deg_s: float
    tilt_speed_deg_s: float

    def as_dict(self) -> dict:
        return {
            "t_s": self.t_s,
            "pan_deg": self.pan_deg,
            "tilt_deg": self.tilt_deg,
            "pan_speed_deg_s": self.pan_speed_deg_s,
            "tilt_speed_deg_s": self.tilt_speed_deg_s,
        }


# ------------------------------------------------------------------------------------------------
# the unit's speed curve
# ------------------------------------------------------------------------------------------------
def unit_speed_table(
    rng: np.random.Generator, vmax: float, turbo: float | None, p: HeadParams
) -> np.ndarray:
    """Speed [deg/s] for each byte 0-255 of one axis of one unit (turbo at 0xFF if given).

    Bytes 0x40-0xFE act as 0x3F; without a turbo 0xFF acts as 0x3F too.
    """
    b0 = int(np.clip(p.dead_zone_byte + rng.integers(-1, 2), 0, 61))
    gamma = p.curve_gamma * math.exp(p.unit_gamma_spread * rng.standard_normal())
    gain = max(0.5, 1.0 + p.unit_gain_spread * rng.standard_normal())
    b = np.arange(b0, MAX_SPEED_BYTE + 1)
    x = (b - b0) / (MAX_SPEED_BYTE - b0)
    nominal = x**gamma
    steps = np.diff(nominal) * np.exp(p.unit_step_spread * rng.standard_normal(len(b) - 1))
    curve = np.concatenate(([0.0], np.cumsum(steps)))
    curve /= curve[-1]
    table = np.empty(256)
    table[: b0 + 1] = 0.0
    table[b0:MAX_SPEED_BYTE + 1] = gain * vmax * curve
    table[MAX_SPEED_BYTE + 1:] = table[MAX_SPEED_BYTE]
    if turbo is not None:
        t_gain = max(0.5, 1.0 + p.unit_gain_spread * rng.standard_normal())
        table[PAN_TURBO] = max(t_gain * turbo, 1.05 * table[MAX_SPEED_BYTE])
    return table
