"""Risley-prism optics: the description of a scanner (prisms, channels, point rate).

Paper Section III.A (Fig. 2, 3) and Appendix B. A scanner is a stack of rotating wedge prisms on one
axis, a transceiver that fires at a constant point rate, and optionally a multi-channel transceiver
array (Section III.D.1, Fig. 8) whose channels enter the prisms at small angular offsets.

Frames (written down once, used everywhere in ``sim.scan``)
------------------------------------------------------------
* **Optics frame**: the beam enters along ``+z``; ``x``/``y`` span the aperture.  A prism's phase
  ``theta`` is the direction (from ``+x`` toward ``+y``) in which it deflects the beam, so the exact
  and the paraxial models agree on what a phase means.
* **Lidar frame** (Livox): ``X`` forward, ``Y`` left, ``Z`` up.  ``X = z_opt``, ``Y = x_opt``,
  ``Z = y_opt`` (a cyclic permutation, so both are right-handed).  A Horizon-style oscillator along
  ``x_opt`` is therefore horizontal, and channels stacked along ``y_opt`` are vertical.

Wedge faces
-----------
Each prism has one face perpendicular to the axis and one tilted by the wedge angle ``alpha``.  Which
face is tilted changes the deviation (n = 1.51, alpha = 18 deg: 9.81 deg exit-tilted vs 9.37 deg
entry-tilted, see ``shared/facts/risley-optics.md``), so it is a parameter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction
from typing import Any, Mapping

TILTED_FACES = ("entry", "exit")


class OpticsError(ValueError):
    """An optics description is invalid; the message names the key and what is allowed."""


@dataclass(frozen=True)
class Prism:
    """One rotating wedge prism.

    Parameters
    ----------
    wedge_deg : float in (0, 60) [deg]
        Wedge angle alpha between the two faces.
    index : float in (1, 4]
        Refractive index n at the laser wavelength (905 nm).
    tilted_face : {"entry", "exit"}
        Which face is tilted; the other is perpendicular to the axis.
    rpm : float [rev/min]
        Rotation speed; the sign is the direction (positive: counter-clockwise seen along ``+z``).
    phase_deg : float [deg]
        Deflection direction at t = 0.
    """

    wedge_deg: float
    index: float
    tilted_face: str = "exit"
    rpm: float = 0.0
    phase_deg: float = 0.0

    def __post_init__(self) -> None:
        if not (0.0 < self.wedge_deg < 60.0):
            raise OpticsError(f"wedge_deg = {self.wedge_deg!r}: must be in (0, 60) degrees")
        if not (1.0 < self.index <= 4.0):
            raise OpticsError(f"index = {self.index!r}: must be in (1, 4]")
        if self.tilted_face not in TILTED_FACES:
            raise OpticsError(f"tilted_face = {self.tilted_face!r}: allowed {TILTED_FACES}")
        if not math.isfinite(self.rpm) or abs(self.rpm) > 60000:
            raise OpticsError(f"rpm = {self.rpm!r}: must be finite, |rpm| <= 60000")
        if not math.isfinite(self.phase_deg):
            raise OpticsError(f"phase_deg = {self.phase_deg!r}: must be finite")

    @property
    def thin_prism_deviation_deg(self) -> float:
        """First-order deviation :math:`\\delta = (n - 1)\\alpha` [deg] (paper Fig. 3a)."""
        return (self.index - 1.0) * self.wedge_deg


@dataclass(frozen=True)
class RisleyOptics:
    """A complete scanner: prisms in beam order, point rate and transceiver channels.

    Parameters
    ----------
    prisms : tuple of Prism, 2 or 3 of them
    point_rate_hz : int in [1e3, 2e6] [points/s]
        Total ranging rate over all channels.  An integer so that point times are exact
        (``t_k = k / rate``) and phases can be kept exact over days.
    channel_offsets_deg : tuple of (x_deg, y_deg)
        Incident-beam angular offset of each transceiver channel in the optics frame (Fig. 8a:
        dies side by side in the focal plane).  Point ``k`` is fired by channel ``k mod C``
        (Livox: line id = point index mod 6).
    beam_divergence_deg : (horizontal, vertical) [deg]
        Full-angle beam divergence, used by the footprint coverage definition.
    name : str
        Label shown in reports.
    head_yaw_deg : tuple of float [deg], one per channel, each in [-90, 90]; or () for none
        Several scan heads in one housing (Livox Mid-100: three Mid-40s): channel ``c``'s beam,
        after the prisms, is turned by ``head_yaw_deg[c]`` about the lidar's Z axis (positive toward
        +Y, left).  The heads share the prisms' phases (one pattern, turned): a simplification, the
        real heads run their own motors.
    """

    prisms: tuple[Prism, ...]
    point_rate_hz: int = 100_000
    channel_offsets_deg: tuple[tuple[float, float], ...] = ((0.0, 0.0),)
    beam_divergence_deg: tuple[float, float] = (0.28, 0.03)
    name: str = "custom"
    head_yaw_deg: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        if not (2 <= len(self.prisms) <= 3):
            raise OpticsError(f"prisms: {len(self.prisms)} given, 2 or 3 allowed")
        rate = self.point_rate_hz
        if isinstance(rate, float) and rate.is_integer():
            object.__setattr__(self, "point_rate_hz", int(rate))
        if not isinstance(self.point_rate_hz, int) or not (1_000 <= self.point_rate_hz <= 2_000_000):
            raise OpticsError(
                f"point_rate_hz = {rate!r}: must be a whole number of points/s in [1000, 2000000]"
            )
        if len(self.channel_offsets_deg) < 1:
            raise OpticsError("channel_offsets_deg: at least one channel is needed")
        for i, off in enumerate(self.channel_offsets_deg):
            if len(off) != 2 or not all(math.isfinite(v) and abs(v) < 20 for v in off):
                raise OpticsError(
                    f"channel_offsets_deg[{i}] = {off!r}: must be [x_deg, y_deg] with |value| < 20"
                )
        if self.head_yaw_deg and (len(self.head_yaw_deg) != len(self.channel_offsets_deg)
                                  or not all(math.isfinite(v) and abs(v) <= 90 for v in self.head_yaw_deg)):
            raise OpticsError(
                f"head_yaw_deg = {self.head_yaw_deg!r}: one angle in [-90, 90] degrees per channel "
                f"({len(self.channel_offsets_deg)}), or none"
            )
        if len(self.beam_divergence_deg) != 2 or not all(0 < v < 5 for v in self.beam_divergence_deg):
            raise OpticsError(
                f"beam_divergence_deg = {self.beam_divergence_deg!r}: two values in (0, 5) degrees"
            )

    @property
    def channels(self) -> int:
        return len(self.channel_offsets_deg)

    @property
    def point_interval_s(self) -> float:
        return 1.0 / self.point_rate_hz

    def revs_per_point(self, i: int) -> Fraction:
        """Exact revolutions of prism ``i`` per point interval, ``rpm / (60 * rate)``.

        The float ``rpm`` is taken at its exact binary value, so the phase of point ``k`` is the
        exact rational ``k * revs_per_point`` and can be evaluated without a growing float error.
        """
        return Fraction(self.prisms[i].rpm) / (60 * self.point_rate_hz)

    def repeat_period_s(self) -> float | None:
        """Exact repeat period of the noise-free continuous pattern (paper eq. 5-7), or None if > 1e9 s.

        T = the smallest t with rpm_i t / 60 an integer for every prism.  The sampled points repeat
        only if, in addition, T x point_rate_hz is a whole number of points.
        """
        rates = [Fraction(p.rpm) / 60 for p in self.prisms if p.rpm != 0]
        if not rates:
            return 0.0
        # T * r_i integer for all i  <=>  T multiple of 1/r_i; least common multiple of rationals.
        period = Fraction(0)
        for r in rates:
            unit = 1 / abs(r)
            period = unit if period == 0 else _lcm_fraction(period, unit)
        return float(period) if period < 1e9 else None

    def with_(self, **changes: Any) -> "RisleyOptics":
        from dataclasses import replace

        return replace(self, **changes)

    def with_prism(self, i: int, **changes: Any) -> "RisleyOptics":
        from dataclasses import replace

        prisms = list(self.prisms)
        prisms[i] = replace(prisms[i], **changes)
        return replace(self, prisms=tuple(prisms))


def _lcm_fraction(a: Fraction, b: Fraction) -> Fraction:
    return Fraction(math.lcm(a.numerator, b.numerator), math.gcd(a.denominator, b.denominator))


_PRISM_KEYS = {"wedge_deg", "index", "tilted_face", "rpm", "phase_deg"}
_OPTICS_KEYS = {"prisms", "point_rate_hz", "channel_offsets_deg", "beam_divergence_deg", "name", "head_yaw_deg"}


def optics_from_table(table: Mapping[str, Any], where: str = "optics") -> RisleyOptics:
    """Build optics from a TOML-style table; errors name ``where`` and the key.

    Example (TOML)::

        [lidar]
        point_rate_hz = 100000
        [[lidar.prisms]]
        wedge_deg = 18.0
        index = 1.51
        tilted_face = "exit"
        rpm = 7294
    """
    if not isinstance(table, Mapping):
        raise OpticsError(f"{where}: must be a table of optics keys {sorted(_OPTICS_KEYS)}")
    unknown = set(table) - _OPTICS_KEYS
    if unknown:
        raise OpticsError(f"{where}: unknown key(s) {sorted(unknown)}; allowed {sorted(_OPTICS_KEYS)}")
    if "prisms" not in table:
        raise OpticsError(f"{where}: missing 'prisms' (a list of 2 or 3 prism tables)")
    if not isinstance(table["prisms"], (list, tuple)):
        raise OpticsError(f"{where}: prisms must be a list of 2 or 3 prism tables ([[lidar.prisms]])")
    prisms = []
    for i, p in enumerate(table["prisms"]):
        pw = f"{where}.prisms[{i}]"
        if not isinstance(p, Mapping):
            raise OpticsError(f"{pw}: must be a table with keys {sorted(_PRISM_KEYS)}")
        unknown = set(p) - _PRISM_KEYS
        if unknown:
            raise OpticsError(f"{pw}: unknown key(s) {sorted(unknown)}; allowed {sorted(_PRISM_KEYS)}")
        missing = {"wedge_deg", "index"} - set(p)
        if missing:
            raise OpticsError(f"{pw}: missing key(s) {sorted(missing)}")
        try:
            prisms.append(Prism(**{k: (v if k == "tilted_face" else float(v)) for k, v in p.items()}))
        except (OpticsError, TypeError, ValueError) as exc:
            raise OpticsError(f"{pw}: {exc}") from None
    kwargs = optics_overrides({k: v for k, v in table.items() if k != "prisms"}, where)
    kwargs["prisms"] = tuple(prisms)
    kwargs.setdefault("name", "custom")
    try:
        return RisleyOptics(**kwargs)
    except OpticsError as exc:
        raise OpticsError(f"{where}: {exc}") from None


def _numbers(value, n: int | None, key: str, where: str) -> tuple[float, ...]:
    bad = OpticsError(f"{where}: {key} must be a list of {n if n else 'some'} numbers, got {value!r}")
    if isinstance(value, (str, bytes)) or not isinstance(value, (list, tuple)) or (n is not None and len(value) != n):
        raise bad
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        raise bad
    return tuple(float(v) for v in value)


def optics_overrides(table: Mapping[str, Any], where: str) -> dict[str, Any]:
    """Type-checked optics fields other than prisms (for custom optics and preset overrides)."""
    kwargs: dict[str, Any] = {}
    if "point_rate_hz" in table:
        kwargs["point_rate_hz"] = table["point_rate_hz"]
    if "channel_offsets_deg" in table:
        offs = table["channel_offsets_deg"]
        if isinstance(offs, (str, bytes)) or not isinstance(offs, (list, tuple)) or not offs:
            raise OpticsError(f"{where}: channel_offsets_deg must be a list of [x_deg, y_deg] pairs, got {offs!r}")
        kwargs["channel_offsets_deg"] = tuple(_numbers(c, 2, f"channel_offsets_deg[{i}]", where)
                                              for i, c in enumerate(offs))
    if "beam_divergence_deg" in table:
        kwargs["beam_divergence_deg"] = _numbers(table["beam_divergence_deg"], 2, "beam_divergence_deg", where)
    if "head_yaw_deg" in table:
        kwargs["head_yaw_deg"] = _numbers(table["head_yaw_deg"], None, "head_yaw_deg", where)
    if "name" in table:
        kwargs["name"] = str(table["name"])
    return kwargs


@dataclass(frozen=True)
class SpeedNoise:
    """Motor speed errors that break commensurability (paper Section III.C, Fig. 7).

    Parameters
    ----------
    sigma_frac : float >= 0
        1-sigma relative speed error, drawn independently per prism and per segment (paper: 1 %).
    segment_s : float > 0 [s]
        How long one speed error holds (the motor controller's correction time).
    drift_frac : float >= 0
        Amplitude of a slow sinusoidal relative speed drift (thermal, supply).
    drift_period_s : float > 0 [s]
    """

    sigma_frac: float = 0.01
    segment_s: float = 0.01
    drift_frac: float = 0.0
    drift_period_s: float = 600.0

    def __post_init__(self) -> None:
        if not (0 <= self.sigma_frac < 0.5):
            raise OpticsError(f"speed noise sigma_frac = {self.sigma_frac!r}: must be in [0, 0.5)")
        if not (self.segment_s > 0):
            raise OpticsError(f"speed noise segment_s = {self.segment_s!r}: must be > 0")
        if not (0 <= self.drift_frac < 0.5):
            raise OpticsError(f"speed noise drift_frac = {self.drift_frac!r}: must be in [0, 0.5)")
        if not (self.drift_period_s > 0):
            raise OpticsError(f"speed noise drift_period_s = {self.drift_period_s!r}: must be > 0")

