"""One calibration of a fresh simulated unit, shared by the calibration and reconstruction tests."""

from functools import lru_cache
from pathlib import Path

import numpy as np

from foveatrack.speed_table import TURBO

ROOT = Path(__file__).resolve().parents[2]
# A unit seed no scene, test or doc uses anywhere else (grep unit_seed): the calibration has never seen it.
FRESH_UNIT = 4242
# Every 4th pan byte + 63 + turbo, 11 tilt bytes, 4 s legs: ~200 s of virtual time (~20-60 s wall).
# Bytes in between are interpolated (reported as unmeasured, "not in the plan").
PLAN = dict(pan_bytes=tuple(range(4, 64, 4)) + (63, TURBO), tilt_bytes=(4, 8, 12, 16, 20, 24, 32, 40, 48, 56, 63),
            dwell_s=4.0)


@lru_cache(maxsize=1)
def fresh_unit_calibration():
    from sim.calibration_run import default_plan, run_calibration
    from sim.scene import load_scene

    scene = load_scene(ROOT / "scenes" / "calibration-room.toml")
    return run_calibration(scene, default_plan(scene, **PLAN), unit_seed=FRESH_UNIT, date="2025-01-01T00:00:00Z")


def corner_points(corner_w, rng, n=400):
    """A room's corner for the synthetic calibration rigs: points on its three planes (front wall
    x = cx, left wall y = cy, ceiling z = cz) within 1 m of it on the room's inner side, 3 mm noise."""
    cx, cy, cz = corner_w
    u = rng.uniform(0.0, 1.0, (3, n, 2))
    walls = [np.column_stack([np.full(n, cx), cy - u[0, :, 0], cz - u[0, :, 1]]),
             np.column_stack([cx - u[1, :, 0], np.full(n, cy), cz - u[1, :, 1]]),
             np.column_stack([cx - u[2, :, 0], cy - u[2, :, 1], np.full(n, cz)])]
    return np.vstack(walls) + rng.normal(0.0, 0.003, (3 * n, 3))


class SyntheticHead:
    """A head for the synthetic rigs: turns at the commanded speed (15 deg/s pan, 2 deg/s tilt at byte
    63, linear in the byte) from the moment a command is sent; its tilt holds at ``tilt_stop_deg``."""

    def __init__(self, tilt0_deg: float, tilt_stop_deg: float = float("inf")):
        self.pan, self.tilt, self.t = 0.0, tilt0_deg, 0.0
        self.v = (0.0, 0.0)
        self.max_tilt = tilt0_deg
        self.tilt_stop_deg = tilt_stop_deg

    def advance(self, t):
        dt = t - self.t
        self.pan += self.v[0] * dt
        self.tilt = min(self.tilt + self.v[1] * dt, self.tilt_stop_deg)
        self.max_tilt = max(self.max_tilt, self.tilt)
        self.t = t

    def send(self, t, cmd):
        self.advance(t)
        self.v = (cmd.pan_dir * cmd.pan_byte / 63 * 15.0, cmd.tilt_dir * cmd.tilt_byte / 63 * 2.0)


def corner_frames(head, rng, corner_w, rate_hz: float, max_s: float, mount=None):
    """Frames of the corner ``corner_w`` seen by a lidar on ``head`` (a :class:`SyntheticHead`), its
    pose every 50 points (2.5 ms at 20 Hz) across each frame; ``mount`` (3, 3): lidar -> tilt stage
    (None: none)."""
    from foveatrack.frames import Frame
    from foveatrack.reconstruction import rotation_matrix

    for k in range(int(round(max_s * rate_hz))):
        t0, t1 = k / rate_hz, (k + 1) / rate_hz
        pts = corner_points(corner_w, rng)
        t = np.sort(rng.uniform(t0, t1, len(pts)))
        xyz = np.empty_like(pts)
        for i in range(0, len(pts), 50):
            head.advance(t[i])
            r = rotation_matrix(head.pan, head.tilt)           # world -> lidar: R.T p
            xyz[i:i + 50] = pts[i:i + 50] @ r if mount is None else pts[i:i + 50] @ r @ mount
        head.advance(t1)
        yield Frame(t0, t1, xyz, (t * 1e9).astype(np.int64))
