"""``foveatrack simulate SCENE.toml``: run a scene's closed loop in virtual time."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

from foveatrack.errors import UserError


def register(sub) -> None:
    p = sub.add_parser("simulate", help="run a scene's closed loop (lidar, UAV, head over UART, tracker)")
    p.add_argument("scene", metavar="SCENE.toml", help="a scene file (see scenes/)")
    p.add_argument("--out", metavar="DIR", help="write the recording (run.mcap), summary.json and plots here")
    p.add_argument("--overwrite", action="store_true",
                   help="replace a recording (run.mcap) that --out already holds (else refused)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument("--plot", action="store_true", help="write the Fig. 14 a/b/c plots into --out (a [tracker.sky] run: tracks.png)")
    p.add_argument("--seed", type=int, help="override the scene's seed")
    p.add_argument("--duration", type=float, metavar="S", help="override the scene's duration")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    p.add_argument("--live", nargs="?", const=8765, default=None, metavar="PORT",
                   help="serve the run to Foxglove (ws://127.0.0.1:PORT, default 8765), paced at --speed")
    p.add_argument("--speed", type=float, default=1.0, metavar="FACTOR",
                   help="with --live: virtual seconds per wall second (default 1 = real time)")
    p.add_argument("--live-origin", action="append", default=[], metavar="ORIGIN",
                   help="with --live: also let a web page at ORIGIN (scheme://host[:port]; * for any) read the live "
                        "view; by default only clients without an Origin (the Foxglove app, scripts) and Foxglove's "
                        "web app (https://app.foxglove.dev) are served, so another page in a local browser cannot read it")
    p.add_argument("--linger-s", type=float, default=30.0, metavar="S",
                   help="with --live: after the run, keep serving a connected viewer until it disconnects, "
                        "at most S seconds (default 30; 0: close at once)")
    cores = p.add_mutually_exclusive_group()
    cores.add_argument("--one-thread", action="store_true",
                       help="do not trace the scan and draw the random values of the coming frames on a second "
                            "thread, and write the recording on the loop's thread, not from a child process (same "
                            "results, same file; for many runs side by side, or a one-core machine).  Default: a "
                            "second core is used where one is free (no other task runnable, a low load average)")
    cores.add_argument("--second-core", action="store_true",
                       help="use a second thread and a writer process whatever the load")
    p.set_defaults(func=cmd_simulate)


class CompileNotice:
    """Says on stderr that the numba kernels are compiling when the first frame takes longer than
    ``after_s`` (a first run after an install: about a minute; a warm start loads them in ~0.5 s and
    says nothing), and how long it took once :meth:`done` is called."""

    MESSAGE = ("compiling the numba kernels (about a minute, once per install; `foveatrack warmup` "
               "does it ahead) ...")

    def __init__(self, enabled: bool = True, after_s: float = 2.0, stream=None):
        import threading
        import time

        self._stream = stream if stream is not None else sys.stderr
        self._t0 = time.perf_counter()
        self._said = False
        self._lock = threading.Lock()
        self._timer = None
        if enabled:
            self._timer = threading.Timer(after_s, self._say)
            self._timer.daemon = True
            self._timer.start()

    def _say(self) -> None:
        with self._lock:
            if self._timer is None:
                return
            self._said = True
            print(self.MESSAGE, file=self._stream, flush=True)

    def done(self) -> None:
        import time

        with self._lock:
            if self._timer is None:
                return
            self._timer.cancel()
            self._timer = None
            if self._said:
                from foveatrack.cli.kernel_cache import cached_text

                print(f"kernels ready after {time.perf_counter() - self._t0:.0f} s ({cached_text()})",
                      file=self._stream, flush=True)


def core_free(load_1min: float | None = None, others_running: int | None = None, cores: int | None = None) -> bool:
    """Whether a core is free for a second thread and a writer process, which only pay where a core
    is idle (on a busy machine they compete with the loop: docs/speed.md, docs/recordings.md).

    Free: no more than ``cores - 2`` other tasks runnable right now (Linux ``/proc/loadavg``, the
    median of five looks 2 ms apart; this run's loop takes a core, and a job between two of its
    processes shows as runnable most of the time), and a 1-minute load average of at most
    ``cores - 0.5`` (no other job has held the machine; one earlier run of ours counts about one).
    """
    cores = (os.cpu_count() or 1) if cores is None else cores
    if cores < 2:
        return False
    if load_1min is None:
        try:
            load_1min = os.getloadavg()[0]
        except OSError:         # no load average on this platform: count the tasks only
            load_1min = 0.0
    if others_running is None:
        others_running = _others_running()
    return others_running <= cores - 2 and load_1min <= cores - 0.5


def _others_running() -> int:
    """Tasks runnable now besides the one asking (0 where ``/proc/loadavg`` does not exist)."""
    import statistics
    import time

    counts = []
    for _ in range(5):
        try:
            with open("/proc/loadavg") as fh:
                counts.append(int(fh.read().split()[3].split("/")[0]) - 1)
        except (OSError, IndexError, ValueError):
            return 0
        time.sleep(0.002)
    return int(statistics.median(counts))


def run_and_report(scene_path, out=None, want_json=False, plot=False, seed=None, duration=None, progress=True,
                   quiet=False, live_port=None, speed=1.0, ahead=None, recording_process=None,
                   linger_s=0.0, live_origins=(), overwrite=False) -> dict:
    """Run a scene and report it (the ``simulate`` command).  ``overwrite``: replace the recording
    ``out`` holds from an earlier run (else a UserError before the run).  ``ahead``: trace the scan ahead on a second
    thread; ``recording_process``: write the recording from a child process.  None: both where a core is
    free (:func:`core_free`); the results and the file are the same either way."""
    from foveatrack.recording import writer_process

    _compile_kernels_first(scene_path, progress)
    # asked only where the caller left the choice (it samples /proc/loadavg for ~10 ms)
    spare = core_free() if ahead is None or recording_process is None else None
    if recording_process is None:
        recording_process = spare and writer_process.available()
    # started first: the child's start (imports, kernels) runs beside the set-up below
    child = writer_process.RecordingProcess() if recording_process and out and live_port is None else None
    try:
        return _run_and_report(scene_path, out, want_json, plot, seed, duration, progress, quiet, live_port, speed,
                               spare if ahead is None else ahead, child, linger_s, live_origins, overwrite)
    finally:
        if child is not None:
            child.close()       # a no-op after the run closed it; ends the child if the run failed early


def _compile_kernels_first(scene_path, progress: bool) -> None:
    """On a cold numba cache (a first run after an install), compile the run's kernels in two processes
    at once (:mod:`foveatrack.cli.kernel_compile`) before anything else starts (the recording's child
    process compiles its kernels too), not one after another inside the first frame."""
    from foveatrack.cli import kernel_compile
    from sim.scene import load_scene

    if not kernel_compile.wants_split():
        return
    try:
        load_scene(scene_path)      # a scene the run will refuse: let it say why, without compiling first
    except UserError:
        return
    kernel_compile.compile_split(scene_path, stream=sys.stderr if progress else None)


def _run_and_report(scene_path, out, want_json, plot, seed, duration, progress, quiet, live_port, speed, ahead,
                    child, linger_s=0.0, live_origins=(), overwrite=False) -> dict:
    import time

    import numpy as np
    from tqdm import tqdm

    from foveatrack.cli.stop_signals import raise_if_interrupted
    from foveatrack.recording import RecordingWriter
    from sim.loop import ClosedLoop
    from sim.recorder import SimRecorder, recording_meta
    from sim.scene import load_scene, with_run_overrides
    from sim.summary import summarize

    if seed is not None and seed < 0:
        raise UserError(f"--seed {seed}: must be an integer >= 0")
    if duration is not None and not (0 < duration <= 2 * 86400):
        raise UserError(f"--duration {duration}: must be > 0 and at most 172800 s (2 days of virtual time)")
    scene = with_run_overrides(load_scene(scene_path), duration, seed)
    for w in scene.warnings():      # a drone under the ground or at the head runs, and is never seen
        print(f"foveatrack simulate: WARNING: {w}", file=sys.stderr, flush=True)
    frames = int(round(scene.duration_s * scene.tracker.rate_hz))
    if frames < 1:
        raise UserError(f"{scene.path}: duration {scene.duration_s} s is shorter than one tracker frame "
                        f"({1 / scene.tracker.rate_hz:g} s)")
    if plot and out is None:
        raise UserError("--plot needs --out DIR")
    out_dir = Path(out) if out else None
    if out_dir is not None and not overwrite and (out_dir / "run.mcap").exists():
        # an earlier run's recording is not replaced unasked (before the run, not after it)
        raise UserError(f"--out {out_dir}: it holds a recording (run.mcap) of an earlier run; give another --out, "
                        "move it away, or add --overwrite to replace it")
    t0 = time.perf_counter()
    loop = ClosedLoop(scene)        # checks the scene's [tracker.sky] tables: before anything is made
    if out_dir is not None:
        try:
            out_dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise UserError(f"--out {out_dir}: cannot create the output directory ({exc})") from None
    writer = live = None
    pacer = None
    if live_port is not None:
        from foveatrack.recording.live import Pacer, check_port

        live_port = check_port(live_port)
        pacer = Pacer(speed)
    if out_dir is not None or live_port is not None:
        # In a child process or on the loop's own thread, never a thread of its own: the SDK holds the
        # interpreter lock while it encodes and compresses (docs/recordings.md)
        options = dict(meta=recording_meta(scene, loop), overwrite=True, created_utc="virtual time (simulation)",
                       log_time=scene.start_utc_ns)    # log times in UTC from the scene's start_utc
        writer = child.open(out_dir / "run.mcap", **options) if child is not None else \
            RecordingWriter(None if out_dir is None else out_dir / "run.mcap", **options)
        recorder = SimRecorder(writer)
        loop.frame_hook = recorder
        if live_port is not None:
            from foveatrack.recording.live import LiveServer

            live = LiveServer(writer.context, live_port, allowed_origins=live_origins)
            print(f"live view on {live.url} (Foxglove: Open connection -> Foxglove WebSocket), "
                  f"{speed:g}x real time", file=sys.stderr, flush=True)

            def paced(frame, out, loop_):
                recorder(frame, out, loop_)
                pacer.wait(frame.t_end_s)

            loop.frame_hook = paced
    # The first frame loads the numba kernels, or compiles them on a first run: announced if it is slow,
    # and kept out of the progress bar (its rate and ETA would be those of a one-minute frame).
    notice = CompileNotice(enabled=progress)
    bar = None

    def advance(k, total):
        nonlocal bar
        raise_if_interrupted()      # a Ctrl-C that was lost on its way (docs/interrupts.md) stops the run here
        if bar is None:
            notice.done()
            bar = tqdm(total=total, initial=k, desc=scene.name, unit="frame", disable=not progress,
                       file=sys.stderr)
        else:
            bar.update(1)

    finish_s = 0.0
    ran = False
    try:
        log = loop.run(advance, ahead=ahead)
        ran = True
    finally:
        notice.done()
        if bar is not None:
            bar.close()
        if writer is not None:
            # the run is done when its recording is: a writer process may still be on the last frames
            t_close = time.perf_counter()
            writer.close()
            finish_s = time.perf_counter() - t_close
        if live is not None:
            if ran:     # a viewer still watching keeps the server up (not after Ctrl-C or an error)
                live.linger(linger_s, lambda t: print(t, file=sys.stderr, flush=True))
            live.stop()
    wall = time.perf_counter() - t0
    summary = summarize(scene, log, wall, loop, finish_s)
    if writer is not None:
        summary["recording_written_by"] = "a child process" if child is not None else "the loop's thread"
    if out_dir is not None:
        (out_dir / "summary.json").write_text(json.dumps(summary, indent=2))
    if plot:
        _plot_run(scene, log, summary, out_dir, loop)
    if want_json:
        json.dump(summary, sys.stdout, indent=2)
        sys.stdout.write("\n")
    elif not quiet:
        e = summary["tracking_error_deg"]
        fmt = lambda v: "-" if v is None else f"{v:.2f}"  # noqa: E731
        if "sky" in summary:
            print(f"{scene.name}: {summary['frames']} frames, {summary['frames_with_detection']} with the fixated "
                  f"track measured in the fovea (Algorithm 1 in its D)")
        else:
            print(f"{scene.name}: {summary['frames']} frames, {summary['frames_with_detection']} with a detection, "
                  f"{summary['points_on_target_per_frame']:.1f} points on target per frame")
        db = max(scene.tracker.deadband_pan_deg, scene.tracker.deadband_tilt_deg)
        if "sky" in summary:
            from sim.sky_summary import sky_lines

            for line in sky_lines(summary["sky"]):
                print(line)
        elif scene.gimbal.frozen:
            err = log["true_error_deg"]
            i = int(np.nanargmin(err)) if np.isfinite(err).any() else None
            print("  head frozen (paper Fig. 13/14a): no tracking"
                  + (f"; the target passed {err[i]:.2f} deg off the lidar axis at {log['t_end_s'][i]:.1f} s"
                     if i is not None else ""))
        elif summary["acquisition_s"] is None and not summary.get("frames_with_detection"):
            print("  never acquired: no frame had a detection (the target never in the space of interest D "
                  "and the lidar's range and field together?): no tracking error to report")
        elif summary["acquisition_s"] is None:
            print(f"  never acquired (error never under {db + 1:g} deg = dead band + 1 for 5 frames in a row): "
                  "no tracking error to report")
        else:
            print(f"  tracking error after acquisition [deg]: rms {fmt(e['rms'])}  p95 {fmt(e['p95'])}  "
                  f"max {fmt(e['max'])}; acquisition {fmt(summary['acquisition_s'])} s")
        if "reconstruction_error_m" in summary and "sky" not in summary:
            r = summary["reconstruction_error_m"]
            print(f"  reconstructed target position error [m]: rms {fmt(r['rms'])}  p95 {fmt(r['p95'])}  "
                  f"max {fmt(r['max'])}")
        speed = f"  {summary['wall_s']:.2f} s wall, {summary['realtime_factor']:.1f}x real time"
        after = summary.get("realtime_factor_after_first_frame")
        if after is not None and summary["first_frame_s"] > 0.5:
            # on a first run the kernels compile inside the first frame: say so, and the speed without it
            speed += (f" ({summary['first_frame_s']:.1f} s of it the first frame, which loads or compiles the "
                      f"numba kernels; {after:.0f}x after it)")
        wrote = "recording and plots" if plot else "recording"     # plots only with --plot
        print(speed + (f"; {wrote} in {out_dir}/" if out_dir else ""))
    return summary


def _plot_run(scene, log, summary, out_dir, loop=None) -> list[Path]:
    """The run's plots (paper Fig. 14 a/b/c and the head angles) into ``out_dir``; for a run of the
    multi-object tracker its tracks and the head angles (Fig. 14's figures are of one target)."""
    from foveatrack.cli import sim_plots

    name, cfg = scene.name, scene.tracker
    if "sky" in summary and loop is not None:
        from sim.sky_summary import sky_plot_data

        return [sim_plots.plot_sky_tracks(sky_plot_data(loop, log), f"{name}: every track (multi-object tracker)",
                                          out_dir / sim_plots.TRACKS_PNG),
                sim_plots.plot_head(log["t_end_s"], log["head_pan_deg"], log["head_tilt_deg"], f"{name}: head angles",
                                    out_dir / sim_plots.HEAD_PNG, est_pan_deg=log["est_pan_deg"],
                                    est_tilt_deg=log["est_tilt_deg"], state=log["state"],
                                    tilt_limits_deg=cfg.tilt_limits_deg, tilt_margin_deg=cfg.tilt_margin_deg)]
    t = log["t_end_s"]
    db = max(cfg.deadband_pan_deg, cfg.deadband_tilt_deg)
    frozen = " (head frozen)" if scene.gimbal.frozen else ""
    if scene.gimbal.frozen:   # nothing is tracked: no acquisition phase to mark, no dead band at work
        err_title, phases = f"{name}: target angle off the fixed lidar axis (head frozen)", {}
    else:
        err_title = f"{name}: tracking error (paper Fig. 14b)"
        phases = dict(deadband_deg=db, in_fov_t_s=summary["in_fov_t_s"], acquired_t_s=summary["acquired_t_s"],
                      deadband_axes_deg=(cfg.deadband_pan_deg, cfg.deadband_tilt_deg))
        if "true_az_deg" in log and "true_el_deg" in log:
            phases["axis_error_deg"] = (log["true_az_deg"], log["true_el_deg"])
    return [
        sim_plots.plot_error_vs_time(t, log["true_error_deg"], err_title, out_dir / sim_plots.ERROR_PNG,
                                     detected=log["detected"], half_fov_deg=summary["half_fov_deg"], **phases),
        sim_plots.plot_points_vs_position(
            log["target_xyz"], log["true_error_deg"], log["points_on_target"],
            f"{name}: points on the UAV per frame{frozen}", out_dir / sim_plots.POINTS_PNG,
            half_fov_deg=summary["half_fov_deg"]),
        sim_plots.plot_trajectory(t, log["estimate_xyz"], f"{name}: reconstructed trajectory (paper Fig. 14c)",
                                  out_dir / sim_plots.TRAJECTORY_PNG, true_xyz=log["target_xyz"]),
        sim_plots.plot_head(t, log["head_pan_deg"], log["head_tilt_deg"], f"{name}: head angles{frozen}",
                            out_dir / sim_plots.HEAD_PNG, est_pan_deg=log["est_pan_deg"], est_tilt_deg=log["est_tilt_deg"],
                            state=log["state"], tilt_limits_deg=cfg.tilt_limits_deg,
                            tilt_margin_deg=cfg.tilt_margin_deg),
    ]


def _cores_flag(args) -> bool | None:
    return False if args.one_thread else True if args.second_core else None


def cmd_simulate(args) -> int:
    if args.live_origin and args.live is None:
        raise UserError("--live-origin is for the live view: add --live")
    if args.speed != 1.0 and args.live is None:
        # --speed paces only the live view; without it the run goes as fast as it can, so the flag did nothing
        raise UserError(f"--speed {args.speed:g} paces the live view: add --live, or leave --speed out "
                        "(without --live the run goes as fast as the machine allows)")
    run_and_report(args.scene, args.out, args.json, args.plot, args.seed, args.duration, not args.no_progress,
                   live_port=args.live, speed=args.speed, ahead=_cores_flag(args), recording_process=_cores_flag(args),
                   linger_s=max(args.linger_s, 0.0), live_origins=args.live_origin, overwrite=args.overwrite)
    return 0
