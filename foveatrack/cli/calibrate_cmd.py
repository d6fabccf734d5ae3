"""``foveatrack calibrate``: measure the head's speed table by tracking a room corner (paper App. D.4).

Simulated::

    foveatrack calibrate --scene scenes/calibration-room.toml [--unit-seed N] [--out table.json]
                         [--plot F.png] [--json]

runs :class:`foveatrack.calibration.Calibrator` against the simulated PTS-303H over the virtual UART
(``sim.calibration_run``), writes the speed table (JSON: unit, date, per-entry uncertainty; see
:mod:`foveatrack.speed_table`), prints the entries it could not measure and, since the unit's truth is
known in simulation, each measured entry's error.

Real hardware (a Livox and a head on a serial port) is driven the same way: any frame source and any
command sink go through :class:`CalibrationDriver` / :func:`drive_calibration`; the live wiring
(``--lidar/--serial``) is not in this command yet.
"""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Callable, Iterable

import numpy as np

from foveatrack.calibration import CalibrationPlan, Calibrator, FeatureSpec
from foveatrack.control import STOP, HeadCommand
from foveatrack.errors import UserError
from foveatrack.frames import Frame
from foveatrack.speed_table import TURBO, SpeedTable


class PriorAxisCalibrator(Calibrator):
    """A :class:`Calibrator` whose rotation-axis estimates are pulled toward the known mounting.

    The base class finds each head axis in the lidar frame as the smallest eigenvector ``v0`` of the
    pooled scatter of corner positions (eigenvalues ``w0 <= w1 <= w2``) and uses it as is.  With the
    excursions a lidar FoV allows (15 deg arcs) that direction is poorly determined toward ``v1``
    (the arc's sagitta): seen over several scene seeds the implied start tilt scattered by about
    1.5 deg, which biases every pan speed alike by ``tan(el) * d_axis`` (about 0.7 % for a corner
    15 deg above the pan plane).  Here the estimate is the inverse-variance combination of the data
    and the prior (pan: ``R_y(start_tilt) z``; tilt: lidar Y):

    .. math:: \\theta_j = \\frac{\\theta_{p,j}/\\sigma_p^2}{1/\\sigma_{d,j}^2 + 1/\\sigma_p^2},
              \\quad \\sigma_{d,j}^2 = \\frac{s^2\\, w_j}{(w_j - w_0)^2},\\quad s^2 = \\frac{w_0}{n - 3},
              \\quad j = 1, 2

    where ``theta_{p,j} = prior . v_j`` and the axis is ``v0 + sum_j theta_j v_j`` normalised
    (first-order perturbation of the eigenvector by noise of variance ``s^2`` per sample).  Only
    legs whose corner moved ``min_arc_rms_m`` (rms along the arc) are pooled: a slow leg adds the
    corner's anisotropic noise and no information (with all 18 tilt bytes pooled the tilt axis came
    out 50 deg off and every tilt speed +2.7 %).  Degenerate scatter (``w0 / w1 > 0.25``) -> prior.

    start_tilt_sigma_deg : float > 0 [deg]  how well the start tilt (``plan.start_tilt_deg``) is
        known: exact in simulation; a levelled head with a known zero about 0.5 deg; give 90 if unknown
    mount_sigma_deg : float > 0 [deg]       lidar Y vs the tilt axis (mounting), about 0.5 deg
    min_arc_rms_m : float >= 0 [m]          legs whose corner moved less are left out of the axis fit
    """

    def __init__(self, plan: CalibrationPlan, feature: FeatureSpec, *, start_tilt_sigma_deg: float = 0.5,
                 mount_sigma_deg: float = 0.5, min_arc_rms_m: float = 0.1, **kw):
        super().__init__(plan, feature, **kw)
        if not (start_tilt_sigma_deg > 0 and mount_sigma_deg > 0):
            raise UserError("start_tilt_sigma_deg and mount_sigma_deg must be > 0 [deg]")
        self.prior_sigma_deg = {"pan": float(start_tilt_sigma_deg), "tilt": float(mount_sigma_deg)}
        self.min_arc_rms_m = float(min_arc_rms_m)

    def _axis_estimate(self, axis: str) -> np.ndarray:
        prior = self._pan_prior if axis == "pan" else np.array([0.0, 1.0, 0.0])
        C = np.zeros((3, 3))
        n = 0
        for leg in self.legs:
            if leg.axis != axis:
                continue
            _, Q = self._steady(leg)
            if len(Q) < self.plan.min_samples:
                continue
            Qc = Q - Q.mean(axis=0)
            # only legs whose arc is long (rms >= min_arc_rms_m along it): a leg that hardly moves
            # carries no information on the axis, only the corner's (anisotropic) noise
            if math.sqrt(np.linalg.eigvalsh(Qc.T @ Qc)[-1] / len(Q)) < self.min_arc_rms_m:
                continue
            C += Qc.T @ Qc
            n += len(Q)
        if n < 10:
            return prior
        w, v = np.linalg.eigh(C)
        a = v[:, 0] if v[:, 0] @ prior > 0 else -v[:, 0]
        if w[1] <= 0 or w[0] / w[1] > 0.25:
            return prior                      # degenerate: the arcs do not tell the axis
        s2 = max(w[0], 0.0) / max(n - 3, 1)
        wp = 1.0 / math.radians(self.prior_sigma_deg[axis]) ** 2
        out = a.copy()
        for j in (1, 2):
            var_d = s2 * w[j] / (w[j] - w[0]) ** 2
            wd = 1.0 / var_d if var_d > 0 else math.inf
            theta_p = float(prior @ v[:, j])
            out += (wp * theta_p / (wd + wp) if math.isfinite(wd) else 0.0) * v[:, j]
        out /= np.linalg.norm(out)
        if out @ prior < math.cos(math.radians(30)):
            return prior
        return out


    def _estimate(self):
        """The base estimate, then the head timing refitted from the legs' whole angle histories.

        The base class reads each entry's effective delay ``dead_time + v / (2 a)`` off the steady
        line's intercept and fits one acceleration to both axes; on the simulated PTS-303 (40 and
        10 deg/s^2, 40 ms) that gave 25-28 ms and 32/8.4 deg/s^2, and the reconstruction, which
        integrates every ramp of a P controller's decelerating approaches, drifted 1.9 deg in pan
        over 60 s (0.4 deg with the true timing).  Here the corner's angle over each whole leg
        (ramp included, up to its stop) is fitted with the head's model (App. D.4 timing as in
        :mod:`foveatrack.reconstruction`):

        .. math:: \\theta(t) = \\begin{cases} 0 & \\tau < 0 \\\\ a\\tau^2/2 & 0 \\le \\tau < v/a \\\\
                  v(\\tau - v/(2a)) & \\text{else} \\end{cases},\\quad
                  \\tau = t - t_{cmd} - \\text{latency} - d

        with ``v`` the entry's measured speed, one dead time ``d`` and one acceleration per axis
        (scipy ``least_squares``, soft-L1 loss), written into ``dead_time_s`` and each
        ``AxisTable.accel_deg_s2`` (the reconstruction uses them per axis).  Legs slower than
        ``0.2 deg/s`` carry no timing information and are left out.
        """
        from dataclasses import replace as _replace

        from scipy.optimize import least_squares

        from foveatrack.calibration import _SIGN, _angle_about

        table, report = super()._estimate()
        axes = {ax: np.asarray(report.axis_lidar[ax], float) for ax in ("pan", "tilt")}
        data = []
        for leg in self.legs:
            ax = table.axis(leg.axis)
            v = ax.speed_deg_s(leg.byte)
            if not ax.is_measured(leg.byte) or not v >= 0.2 or leg.t_stop_s is None or leg.ref_q is None:
                continue
            s = [(t, q) for t, q in leg.samples if leg.t_cmd_s < t <= leg.t_stop_s]
            if len(s) < self.plan.min_samples:
                continue
            t = np.array([x for x, _ in s])
            Q = np.array([q for _, q in s])
            ang = np.degrees(np.unwrap(np.radians(_angle_about(Q, axes[leg.axis], leg.ref_q))))
            ang = _SIGN[leg.axis] * leg.direction * ang
            data.append((0 if leg.axis == "pan" else 1, v, t - leg.t_cmd_s - self.plan.latency_s, ang))
        if len(data) < 4 or len({d[0] for d in data}) < 2:
            return table, report

        def model(tau, v, a):
            tr = v / a
            return np.where(tau < 0, 0.0, np.where(tau < tr, 0.5 * a * tau ** 2, v * (tau - 0.5 * tr)))

        def resid(p):
            d, la_p, la_t = p
            acc = (math.exp(la_p), math.exp(la_t))
            return np.concatenate([ang - model(tau - d, v, acc[k]) for k, v, tau, ang in data])

        x0 = [max(report.dead_time_s, 0.0), math.log(report.accel_deg_s2 or 20.0), math.log(report.accel_deg_s2 or 20.0)]
        fit = least_squares(resid, x0, loss="soft_l1", f_scale=0.1,
                            bounds=([0.0, math.log(0.1), math.log(0.1)], [1.0, math.log(1e4), math.log(1e4)]))
        if not fit.success:
            return table, report
        dead = float(fit.x[0])
        a_pan, a_tilt = math.exp(fit.x[1]), math.exp(fit.x[2])
        table = _replace(table, pan=_replace(table.pan, accel_deg_s2=a_pan),
                         tilt=_replace(table.tilt, accel_deg_s2=a_tilt), dead_time_s=dead,
                         accel_deg_s2=max(a_pan, a_tilt))
        report = _replace(report, dead_time_s=dead, accel_deg_s2=max(a_pan, a_tilt))
        self.axis_accel_deg_s2 = {"pan": a_pan, "tilt": a_tilt}
        return table, report


class CalibrationDriver:
    """Adapter from a :class:`Calibrator` to a loop that sends one command per frame.

    ``driver(frame, send_t_s) -> HeadCommand``: feeds the frame to the calibrator and returns the
    command to send now.  The calibrator's ``None`` ("keep the current command") is turned into the
    latched command, and a finished calibration always gives STOP, so a driver that re-sends every
    frame (the closed-loop simulator, a Pelco-D keep-alive) and one that sends only changes both
    work.  ``sent`` lists ``(send_t_s, command)`` at every change.  This is the ``controller`` of
    ``sim.loop.ClosedLoop``.
    """

    def __init__(self, calibrator: Calibrator):
        self.calibrator = calibrator
        self.current: HeadCommand = STOP
        self.sent: list[tuple[float, HeadCommand]] = []

    @property
    def finished(self) -> bool:
        return self.calibrator.done

    def __call__(self, frame: Frame, send_t_s: float) -> HeadCommand:
        cmd = self.calibrator.step(frame)
        if self.calibrator.done:
            cmd = STOP
        if cmd is not None and cmd != self.current:
            self.current = cmd
            self.sent.append((send_t_s, cmd))
        return self.current


def drive_calibration(calibrator: Calibrator, frames: Iterable[Frame], send: Callable[[float, HeadCommand], None],
                      send_delay_s: float = 0.0) -> CalibrationDriver:
    """Run a calibration from any frame source into any command sink (a real lidar + head, a replay).

    ``frames`` yields consecutive frames (e.g. :class:`foveatrack.frames.FrameSlicer` over a live
    Livox stream); ``send(t_s, command)`` writes the command (e.g. Pelco-D to the head's port) and
    is called once per frame.  Stops consuming frames when the calibration is done (after sending a
    final STOP).  Returns the driver (``driver.calibrator.result()`` is the table).
    """
    driver = CalibrationDriver(calibrator)
    for frame in frames:
        t = frame.t_end_s + send_delay_s
        send(t, driver(frame, t))
        if driver.finished:
            break
    return driver


# ---------------------------------------------------------------------------------------------------
def register(sub) -> None:
    p = sub.add_parser("calibrate", help="measure the head's speed table by tracking a room corner (App. D.4)")
    p.add_argument("--scene", metavar="SCENE.toml", help="simulate: a scene with a room corner in view "
                   "(scenes/calibration-room.toml)")
    p.add_argument("--unit-seed", type=int, metavar="N", help="simulate another unit of the head family")
    p.add_argument("--out", metavar="TABLE.json", default="speed-table.json",
                   help="where to write the speed table (default: %(default)s)")
    p.add_argument("--plot", metavar="F.png", help="plot measured speeds (and the truth, when simulated)")
    p.add_argument("--json", action="store_true", help="print a JSON summary instead of text")
    p.add_argument("--pan-bytes", metavar="B,B,...", help="pan bytes to measure (0-63, 'turbo'); "
                   "others are interpolated (default: 18 bytes + turbo)")
    p.add_argument("--tilt-bytes", metavar="B,B,...", help="tilt bytes to measure (0-63)")
    p.add_argument("--dwell-s", type=float, help="max seconds per leg (default 6)")
    p.add_argument("--corner", type=float, nargs=3, metavar=("X", "Y", "Z"),
                   help="approximate corner position in the lidar frame [m] (simulated: from the scene)")
    p.add_argument("--seed", type=int, default=0, help="RANSAC seed of the corner finder")
    p.add_argument("--lidar", metavar="IP", help="real hardware: the Livox's IP (not yet wired)")
    p.add_argument("--serial", metavar="PORT", help="real hardware: the head's serial port (not yet wired)")
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=cmd_calibrate)


def _bytes(text: str | None, what: str) -> tuple[int, ...] | None:
    if text is None:
        return None
    out = []
    for tok in text.split(","):
        tok = tok.strip().lower()
        if not tok:
            continue
        try:
            out.append(TURBO if tok == "turbo" else int(tok, 0))
        except ValueError:
            raise UserError(f"{what}: {tok!r} is not a byte (0-63, 0x3F, or 'turbo' for pan)") from None
    if not out:
        raise UserError(f"{what}: give at least one byte")
    return tuple(out)


def ranges(bs) -> str:
    """[0, 1, 2, 5, 7, 8] -> '0-2, 5, 7-8' (turbo as 'turbo')."""
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


def unmeasured_summary(report) -> dict:
    """{axis: {reason: [bytes]}} from a CalibrationReport."""
    out = {}
    for axis, d in report.unmeasured.items():
        by = {}
        for b, reason in d.items():
            by.setdefault(reason, []).append(b)
        out[axis] = by
    return out


def cmd_calibrate(args) -> int:
    if args.lidar or args.serial:
        raise UserError("real-hardware calibration (--lidar/--serial): not wired into this command yet; "
                        "drive foveatrack.cli.calibrate_cmd.drive_calibration(Calibrator(...), frames, send) "
                        "from a Livox frame source and a Pelco-D port, or use --scene to calibrate the "
                        "simulated head")
    if not args.scene:
        raise UserError("calibrate needs --scene SCENE.toml (e.g. scenes/calibration-room.toml)")
    run = calibrate_scene(args)
    table = run.table
    table.save(args.out)
    summary = {
        "table": str(args.out), "head": table.head, "date": table.date,
        "frames": run.frames, "virtual_s": round(run.virtual_s, 1), "wall_s": round(run.wall_s, 2),
        "dead_time_s": table.dead_time_s, "accel_deg_s2": table.accel_deg_s2,
        "implied_start_tilt_deg": run.report.implied_start_tilt_deg,
        "head_start_deg": list(run.head_start_deg), "head_end_deg": list(run.head_end_deg),
        "unmeasured": {a: {r: bs for r, bs in d.items()} for a, d in unmeasured_summary(run.report).items()},
        "entries": run.comparison,
        "within_tolerance": sum(r["ok"] for r in run.comparison),
        "measured": len(run.comparison),
    }
    if args.plot:
        _plot(run, args.plot)
    if args.json:
        json.dump(summary, sys.stdout, indent=2, default=_jsonable)
        sys.stdout.write("\n")
        return 0
    print(f"calibrated {table.head}: {run.frames} frames ({run.virtual_s:.0f} s virtual, {run.wall_s:.1f} s wall)")
    print(f"  {'axis':4s} {'byte':>5s} {'measured':>9s} {'sigma':>7s} {'true':>9s} {'error':>8s}")
    for r in run.comparison:
        b = "turbo" if r["byte"] == TURBO else str(r["byte"])
        e = "-" if r["error_pct"] is None else f"{r['error_pct']:+.2f}%"
        print(f"  {r['axis']:4s} {b:>5s} {r['measured_deg_s']:9.4f} {r['sigma_deg_s']:7.4f} {r['true_deg_s']:9.4f} "
              f"{e:>8s}{'' if r['ok'] else '  OUTSIDE max(2 %, 3 sigma)'}")
    print(f"  {summary['within_tolerance']}/{summary['measured']} measured entries within max(2 %, 3 sigma) of the truth")
    for axis, d in summary["unmeasured"].items():
        for reason, bs in d.items():
            print(f"  not measured, {axis}: {ranges(bs)}  ({reason})")
    acc = "-" if table.accel_deg_s2 is None else f"{table.accel_deg_s2:.1f}"
    print(f"  dead time {table.dead_time_s * 1e3:.0f} ms, acceleration {acc} deg/s^2; head back at pan "
          f"{run.head_end_deg[0]:.2f}, tilt {run.head_end_deg[1]:.2f} deg (started {run.head_start_deg[0]:.2f}, "
          f"{run.head_start_deg[1]:.2f})")
    print(f"  table written to {args.out}")
    return 0


def calibrate_scene(args):
    from sim.calibration_run import default_plan, run_calibration
    from sim.scene import load_scene

    scene = load_scene(args.scene)
    kw = {}
    pb, tb = _bytes(args.pan_bytes, "--pan-bytes"), _bytes(args.tilt_bytes, "--tilt-bytes")
    if pb is not None:
        kw["pan_bytes"] = pb
    if tb is not None:
        kw["tilt_bytes"] = tb
    if args.dwell_s is not None:
        kw["dwell_s"] = args.dwell_s
    plan = default_plan(scene, **kw)
    feature = FeatureSpec(tuple(args.corner)) if args.corner else None
    progress = None
    bar = None
    if not args.no_progress and not args.json:
        from tqdm import tqdm

        bar = tqdm(total=None, desc="calibrating", unit=" s virtual", file=sys.stderr, leave=False)
        last = [0.0]

        def progress(t_s, budget_s):
            if t_s - last[0] >= 1.0:
                bar.update(t_s - last[0])
                last[0] = t_s
    try:
        return run_calibration(scene, plan, feature, unit_seed=args.unit_seed, seed=args.seed, progress=progress)
    finally:
        if bar is not None:
            bar.close()


def _jsonable(o):
    if isinstance(o, float) and not math.isfinite(o):
        return None
    try:
        return float(o)
    except (TypeError, ValueError):
        return str(o)


def _plot(run, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, axs = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, axis in zip(axs, ("pan", "tilt")):
        tr = run.truth.axis(axis)
        b = np.arange(64)
        ax.plot(b, [tr.speed_deg_s(int(x)) for x in b], "-", color="0.6", label="true (simulated unit)")
        rows = [r for r in run.comparison if r["axis"] == axis and r["byte"] != TURBO]
        ax.errorbar([r["byte"] for r in rows], [r["measured_deg_s"] for r in rows],
                    yerr=[3 * r["sigma_deg_s"] for r in rows], fmt="o", ms=4, capsize=3, label="measured (3 sigma)")
        t = run.table.axis(axis)
        ax.plot(b, [t.speed_deg_s(int(x)) for x in b], ":", lw=1, label="table (interpolated)")
        turbo = [r for r in run.comparison if r["axis"] == axis and r["byte"] == TURBO]
        if turbo:
            ax.errorbar([66], [turbo[0]["measured_deg_s"]], yerr=[3 * turbo[0]["sigma_deg_s"]], fmt="s", ms=4,
                        capsize=3, label="turbo (0xFF), drawn at 66")
            ax.plot([66], [tr.speed_deg_s(TURBO)], "x", color="0.4")
        ax.set_xlabel("speed byte")
        ax.set_ylabel(f"{axis} speed [deg/s]")
        ax.set_title(f"{axis}: speed table ({run.table.head})", fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
