"""A conventional multi-line spinning lidar (paper Fig. 1a, Fig. 10a): the comparison scanner for the
lidar-IMU calibration (Section IV.A).

``vlp16`` — 16 beams fixed in elevation, -15 to +15 deg in 2 deg steps (30 deg vertical FoV), the head
spinning at 10 Hz about the lidar's z axis with a 0.2 deg azimuth step (1800 firings a turn,
18 000 firings/s, 288 000 points/s): the Velodyne VLP-16 ("Puck") in its single-return 10 Hz mode
(Velodyne LiDAR, VLP-16 User Manual 63-9243, Rev. D, 2018: laser elevations table, azimuth
resolution 0.1-0.4 deg at 5-20 Hz, ~300 000 points/s).  The paper's Fig. 10a is "a conventional
16-line mechanical lidar" with these figures.

Simplifications: the 16 lasers fire one after another at equal spacing ``1 / point_rate_hz`` (the
real unit fires them 2.3 us apart, then idles), and the azimuth turns continuously with time; the
pattern repeats every turn exactly (no motor noise), which is the point of the comparison: a longer
accumulation averages range noise but adds no new directions.

:class:`SpinningScanModel` has the parts of :class:`sim.scan.model.ScanModel`'s interface a static
scan needs (``scan``, ``scan_time``, ``index_at_time``, ``optics.point_rate_hz``/``channels``/``name``)
and returns the same :class:`~sim.scan.model.ScanChunk`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim.scan.kernels import RAY_OK
from sim.scan.model import ScanChunk, check_times_fit_ns


@dataclass(frozen=True)
class SpinningOptics:
    name: str
    elevations_deg: tuple
    azimuth_step_deg: float
    rotation_hz: float

    @property
    def channels(self) -> int:
        return len(self.elevations_deg)

    @property
    def firing_rate_hz(self) -> float:
        return 360.0 / self.azimuth_step_deg * self.rotation_hz

    @property
    def point_rate_hz(self) -> int:
        return int(round(self.firing_rate_hz * self.channels))

    @property
    def vertical_fov_deg(self) -> float:
        return max(self.elevations_deg) - min(self.elevations_deg)


VLP16 = SpinningOptics(name="vlp16", elevations_deg=tuple(float(e) for e in range(-15, 16, 2)),
                       azimuth_step_deg=0.2, rotation_hz=10.0)

SPINNING_PRESETS: dict[str, SpinningOptics] = {"vlp16": VLP16}


class SpinningScanModel:
    """Beam directions and times of a spinning multi-line lidar (lidar frame: X fwd, Y left, Z up)."""

    model = "exact"
    speed_noise = None

    def __init__(self, optics: SpinningOptics):
        self.optics = optics
        el = np.radians(np.asarray(optics.elevations_deg, dtype=float))
        self._cos_el = np.cos(el)
        self._sin_el = np.sin(el)

    def index_at_time(self, t_s: float) -> int:
        return int(math.ceil(round(t_s * self.optics.point_rate_hz, 6)))

    def scan(self, k0: int, count: int) -> ScanChunk:
        if k0 < 0 or count < 0:
            raise ValueError(f"k0 = {k0}, count = {count}: both must be >= 0")
        o = self.optics
        k = np.arange(k0, k0 + count, dtype=np.int64)
        c = o.channels
        beam = k % c
        firing = k // c
        # azimuth of the firing, exact for any k: (firing mod firings-per-turn) * step
        per_turn = int(round(360.0 / o.azimuth_step_deg))
        az = np.radians((firing % per_turn) * o.azimuth_step_deg)
        ce = self._cos_el[beam]
        direction = np.column_stack([ce * np.cos(az), ce * np.sin(az), self._sin_el[beam]])
        check_times_fit_ns(k0, count, o.point_rate_hz)
        rate = int(o.point_rate_hz)   # q / r split: k * 1e9 alone would wrap int64 after 9.2e9 points
        t_ns = (k // rate) * 1_000_000_000 + ((k % rate) * 1_000_000_000) // rate
        return ScanChunk(k0=int(k0), t_ns=t_ns.astype(np.int64), direction=direction,
                         channel=beam.astype(np.uint8), status=np.full(count, RAY_OK, dtype=np.uint8))

    def scan_time(self, t0_s: float, t1_s: float) -> ScanChunk:
        k0 = self.index_at_time(t0_s)
        return self.scan(k0, max(0, self.index_at_time(t1_s) - k0))
