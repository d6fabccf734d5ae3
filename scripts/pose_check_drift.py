"""Dead-reckoning drift over minutes of pan travel, with and without the pose check against the
background (issue 26; :mod:`foveatrack.pose_check`).  Simulated time, no daemon: one virtual head
(:class:`gimbal.pts303h.PTS303H`) is driven through a seeded sequence of pan/tilt moves with rests
between them, and two dead reckonings (:class:`foveatrack.reconstruction.Reconstructor`) take the same
commands: one left alone, one corrected by the pose check from the yard scene's lidar frames (ray cast
at the head's true pose of each point's time, every ``period_s`` as the daemon checks).  The map is
built from the first second at rest at 0/0, as the daemon builds it.

    .venv/bin/python scripts/pose_check_drift.py [--minutes 5] [--table examples/pts303h-unit3-speed-table.json]
        [--unit-seed 3] [--plot out/pose_check_drift.png]

Prints, per minute: the pan travel so far and the largest |estimate - truth| in pan and tilt of
each dead reckoning; and the checks' counts.  ``--table nominal`` runs the datasheet's speeds, and
``--unit-seed 7`` with unit 3's table is a speed table of another unit.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from foveatrack.control import STOP, HeadCommand  # noqa: E402
from foveatrack.detection import wrap_deg  # noqa: E402
from foveatrack.pose_check import PoseCheck, PoseCheckConfig  # noqa: E402
from foveatrack.reconstruction import Reconstructor  # noqa: E402
from foveatrack.speed_table import SpeedTable  # noqa: E402
from gimbal.pelco import encode_pan_tilt  # noqa: E402
from gimbal.pts303h import PTS303H  # noqa: E402

YARD = ROOT / "tests" / "daemon" / "scene_yard.toml"
FRAME_S = 0.1
LINK_S = 7 * 10 / 9600          # one Pelco-D frame at 9600 baud


def moves(rng, minutes: float):
    """(t_s, HeadCommand) in time order: moves of 1-3 s at pan bytes 10-50 (tilt now and then), each
    followed by a STOP and a rest of 1-5 s (~2 deg/s of pan travel on average, as the issue's run); pan kept within +-30 deg of home by choosing the
    direction toward it when beyond 15 deg (a commanded, not a true, bound: the head's own speeds
    decide where it really goes)."""
    t, out, pan_cmd = 1.5, [], 0.0           # the first second at rest builds the map
    nominal = 15.0 / 63                     # rough deg/s per byte, only to steer the sequence
    while t < minutes * 60.0:
        byte = int(rng.integers(10, 51))
        dur = float(rng.uniform(1.0, 3.0))
        d = int(rng.choice([-1, 1])) if abs(pan_cmd) < 15.0 else (-1 if pan_cmd > 0 else 1)
        tilt_dir, tilt_byte = (int(rng.choice([-1, 1])), int(rng.integers(10, 40))) if rng.random() < 0.2 else (0, 0)
        out.append((t, HeadCommand(d, byte, tilt_dir, tilt_byte)))
        pan_cmd += d * byte * nominal * dur
        t += dur
        out.append((t, STOP))
        t += float(rng.uniform(1.0, 5.0))
    return out


class YardLidar:
    def __init__(self):
        from sim.scene import load_scene
        from sim.sensor import SceneSensor, scene_scan_model

        self.scene = load_scene(YARD)
        self.sensor = SceneSensor(self.scene)
        self.scan = scene_scan_model(self.scene)

    def frame(self, head, t0: float, t1: float):
        from sim.world import kernels as wk

        chunk = self.scan.scan_time(t0, t1)
        d = np.ascontiguousarray(chunk.direction)
        pan, tilt = head.angles_at(chunk.t_ns * 1e-9, wrap_pan=False)
        out = np.empty_like(d)
        wk.rotate_pan_tilt_kernel(d, np.radians(pan), np.radians(tilt), out)
        xyz, t_ns, _, _ = self.sensor.returns(chunk, out, t0, t1)
        return xyz, t_ns


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=5.0)
    ap.add_argument("--unit-seed", type=int, default=3, help="the virtual head's unit (default 3)")
    ap.add_argument("--table", default=str(ROOT / "examples" / "pts303h-unit3-speed-table.json"),
                    help="the dead reckoning's speed table (a JSON file or 'nominal')")
    ap.add_argument("--seed", type=int, default=1, help="the move sequence's seed")
    ap.add_argument("--plot", metavar="F.png")
    args = ap.parse_args(argv)

    table = SpeedTable.nominal(15.0, 2.0) if args.table == "nominal" else SpeedTable.load(args.table)
    head = PTS303H(unit_seed=args.unit_seed)
    kw = dict(latency_s=LINK_S, tilt_limits_deg=(-30.0, 60.0))
    plain, checked = Reconstructor(table, **kw), Reconstructor(table, **kw)
    cfg = PoseCheckConfig(enabled=True)
    pc = PoseCheck(cfg)
    lidar = YardLidar()
    cmds = moves(np.random.default_rng(args.seed), args.minutes)
    t_end = args.minutes * 60.0
    # events in time order: commands, and checks every period_s after the map
    for k in range(cfg.map_frames):
        xyz, _ = lidar.frame(head, k * FRAME_S, (k + 1) * FRAME_S)
        pc.map_frame(xyz, 0.0, 0.0)
    t_check = cfg.map_frames * FRAME_S + cfg.period_s
    rows, travel, last_pan = [], 0.0, 0.0
    next_row = 1.0
    i = 0
    started = time.perf_counter()
    while t_check < t_end or i < len(cmds):
        t_cmd = cmds[i][0] if i < len(cmds) else math.inf
        if t_cmd <= t_check:
            t, c = cmds[i]
            i += 1
            head.receive(encode_pan_tilt(1, c.pan_dir, c.pan_byte, c.tilt_dir, c.tilt_byte), t + LINK_S)
            plain.on_command(t, c)
            checked.on_command(t, c)
            continue
        if t_check >= t_end:
            break
        t1 = t_check
        t0 = t1 - FRAME_S
        xyz, t_ns = lidar.frame(head, t0, t1)
        res = pc.on_frame(xyz, t_ns, t0, t1, checked.angles_at)
        if res is not None:
            dp, dt = pc.correction(res)
            if dp or dt:
                checked.shift(t0, dp, dt)
        # the truth and both estimates, at 10 Hz between checks
        for t in np.arange(t0 + FRAME_S * 0.5, t1 + 1e-9, FRAME_S):
            tp, tt = (float(v[0]) for v in head.angles_at(np.array([t]), wrap_pan=False))
            travel += abs(tp - last_pan)
            last_pan = tp
            ep = [wrap_deg(r.angles_at(t)[0] - tp) for r in (plain, checked)]
            et = [r.angles_at(t)[1] - tt for r in (plain, checked)]
            rows.append((t, travel, *ep, *et))
        if t_check >= next_row * 60.0:
            next_row += 1
            a = np.array(rows)
            print(f"  {t_check / 60:4.1f} min  pan travel {travel:6.0f} deg  |pan err| now: without {abs(a[-1, 2]):5.2f}, "
                  f"with {abs(a[-1, 3]):5.2f} deg (max {np.abs(a[:, 2]).max():5.2f} / {np.abs(a[:, 3]).max():5.2f})  "
                  f"checks {pc.checks}  [{time.perf_counter() - started:.0f} s]", flush=True)
        t_check += cfg.period_s
    a = np.array(rows)
    print(f"pan travel {travel:.0f} deg in {args.minutes:g} min (head unit {args.unit_seed}, table {Path(args.table).name})")
    print(f"{'':24s}{'without check':>15s}{'with check':>15s}")
    for name, col in (("pan error at the end", 2), ("tilt error at the end", 4)):
        print(f"{name:24s}{a[-1, col]:+14.2f}°{a[-1, col + 1]:+14.2f}°")
    for name, col in (("pan |error| max", 2), ("tilt |error| max", 4)):
        print(f"{name:24s}{np.abs(a[:, col]).max():14.2f}°{np.abs(a[:, col + 1]).max():14.2f}°")
    print(f"pan |error| rms{'':9s}{np.sqrt((a[:, 2] ** 2).mean()):14.2f}°{np.sqrt((a[:, 3] ** 2).mean()):14.2f}°")
    print(f"checks: {pc.checks}; map cells {pc.map.cells_mapped}; table error seen by the witness: "
          f"{pc.witness.table_error_rel if pc.witness.table_error_rel is None else f'{100 * pc.witness.table_error_rel:+.1f} %'}")
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(2, 1, figsize=(9, 6), sharex=True, constrained_layout=True)
        for k, axis in enumerate(("pan", "tilt")):
            ax[k].plot(a[:, 0] / 60, a[:, 2 + 2 * k], label="dead reckoning alone")
            ax[k].plot(a[:, 0] / 60, a[:, 3 + 2 * k], label="with the pose check")
            ax[k].set_ylabel(f"{axis} estimate - truth [deg]")
            ax[k].grid(True, alpha=0.3)
        ax[0].legend()
        ax[1].set_xlabel("time [min]")
        ax[0].set_title(f"dead-reckoning drift, {travel:.0f} deg of pan travel (head unit {args.unit_seed})")
        Path(args.plot).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(args.plot, dpi=110)
        print(f"wrote {args.plot}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
