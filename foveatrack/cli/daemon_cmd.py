"""``foveatrack daemon --config FILE``: the real-time tracker (Livox over UDP in, Pelco-D out).

Runs until SIGINT/SIGTERM (or ``--duration-s``), then stops the head, closes the recording and
exits 0.  A one-line status is shown on stderr when it is a terminal; ``--log FILE`` writes
structured JSON lines (start, lidar/head link events, watchdog, the final counters).
"""

from __future__ import annotations


def register(sub) -> None:
    p = sub.add_parser("daemon", help="real-time tracking: Livox lidar in, Pelco-D head out, recorded")
    p.add_argument("--config", required=True, metavar="FILE.toml", help="daemon config (examples/daemon-virtual.toml)")
    p.add_argument("--log", metavar="FILE", help="structured log, JSON lines (overrides [daemon] log)")
    p.add_argument("--duration-s", type=float, default=None, help="stop after this many seconds")
    p.add_argument("--no-status", action="store_true", help="no live status line even on a terminal")
    p.add_argument("--check", action="store_true", help="validate the config, print it, and exit")
    p.set_defaults(func=cmd_daemon)


def cmd_daemon(args) -> int:
    import json
    import sys

    from foveatrack.daemon import Daemon, load_config
    from foveatrack.errors import UserError

    cfg = load_config(args.config)
    for w in cfg.warnings():
        print(f"foveatrack daemon: WARNING: {w}", file=sys.stderr)
    if args.check:
        print(json.dumps({"lidar": cfg.lidar.__dict__, "head": cfg.head.__dict__,
                          "tracker_overrides": cfg.tracker_overrides, "recording": cfg.recording.__dict__,
                          "daemon": cfg.loop.__dict__}, indent=1, default=str))
        return 0
    if args.duration_s is not None and not args.duration_s > 0:
        raise UserError(f"--duration-s must be > 0, got {args.duration_s}")
    d = Daemon(cfg, log_path=args.log, status=False if args.no_status else None, duration_s=args.duration_s)
    code = d.run()
    s = d.final_stats
    print(f"foveatrack daemon: {s.get('frames', 0)} frames, {s.get('frames_detected', 0)} with a detection; "
          f"processing p99 {s.get('processing_ms_p99', float('nan'))} ms, latency p99 {s.get('latency_ms_p99', float('nan'))} ms"
          f"{'; recording ' + str(d.recording_path) if d.recording_path else ''}", file=sys.stderr)
    for problem in d.problems():
        print(f"foveatrack daemon: {problem}", file=sys.stderr)
    return code
