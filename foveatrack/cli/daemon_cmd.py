"""``foveatrack daemon --config FILE``: the real-time tracker (Livox over UDP in, Pelco-D out).

Runs until SIGINT/SIGTERM (or ``--duration-s``), then stops the head, closes the recording and
exits 0.  A one-line status is shown on stderr when it is a terminal; ``--log FILE`` writes
structured JSON lines (start, lidar/head link events, watchdog, the final counters).

``foveatrack daemon pin ID --config FILE`` / ``foveatrack daemon unpin --config FILE``: tell the
daemon running with that config (``[tracker.sky]``: the multi-object tracker) to make track ID the
fovea's priority, or to let the threat scores choose again; ``foveatrack daemon tracks --config
FILE`` lists the live confirmed tracks (:mod:`foveatrack.daemon.operator`).
"""

from __future__ import annotations

import argparse


def _track_id(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        v = -1
    if v < 0:
        raise argparse.ArgumentTypeError(f"a track id is a whole number >= 0 (as the live view's /tracks and "
                                         f"the daemon's answers name them), not {text!r}")
    return v


def register(sub) -> None:
    p = sub.add_parser("daemon", help="real-time tracking: Livox lidar in, Pelco-D head out, recorded; "
                                      "'daemon pin ID' / 'daemon unpin' talk to a running one")
    p.add_argument("--config", metavar="FILE.toml", help="daemon config (examples/daemon-virtual.toml); required")
    p.add_argument("--log", metavar="FILE", help="structured log, JSON lines (overrides [daemon] log)")
    p.add_argument("--duration-s", type=float, default=None, help="stop after this many seconds")
    p.add_argument("--no-status", action="store_true", help="no live status line even on a terminal")
    p.add_argument("--check", action="store_true", help="validate the config, print it, and exit")
    p.add_argument("--live", nargs="?", const=8765, default=None, metavar="PORT",
                   help="serve the tracking to Foxglove on ws://127.0.0.1:PORT (default 8765)")
    p.add_argument("--live-origin", action="append", default=[], metavar="ORIGIN",
                   help="with --live: also let a web page at ORIGIN (scheme://host[:port]; * for any) read the live "
                        "view; by default only clients without an Origin (the Foxglove app, scripts) and Foxglove's "
                        "web app (https://app.foxglove.dev) are served, so another page in a local browser cannot read it")
    p.set_defaults(func=cmd_daemon)
    ops = p.add_subparsers(dest="operator", metavar="{pin,unpin,tracks}", required=False,
                           title="to a running daemon ([tracker.sky])")
    pin = ops.add_parser("pin", help="hold the fovea on a live confirmed track while it lives (attention.pin_holds_fovea)")
    pin.add_argument("track_id", type=_track_id, metavar="ID", help="the track's id")
    unpin = ops.add_parser("unpin", help="drop the pin: the highest threat is the priority again")
    tracks = ops.add_parser("tracks", help="list the live confirmed tracks (the ids 'pin' takes)")
    for q in (pin, unpin, tracks):
        # SUPPRESS: a --config given before the word (daemon --config F pin 3) is not overwritten
        q.add_argument("--config", default=argparse.SUPPRESS, metavar="FILE.toml",
                       help="the running daemon's config (its [daemon] control_socket, or the default path)")
        q.add_argument("--socket", default=None, metavar="PATH",
                       help="the daemon's control socket, instead of the one --config names")
        q.add_argument("--timeout-s", type=float, default=5.0, help="wait this long for the answer (default 5)")
        q.set_defaults(func=cmd_operator)


def cmd_operator(args) -> int:
    """Send ``pin`` / ``unpin`` to the running daemon, print its answer; status 0 when it was done,
    2 (a UserError) when it was refused or no daemon answered."""
    from pathlib import Path

    from foveatrack.daemon.operator import ask_daemon
    from foveatrack.errors import UserError

    if args.socket is not None:
        path = Path(args.socket)
    elif getattr(args, "config", None) is not None:
        from foveatrack.daemon import load_config

        cfg = load_config(args.config)
        if not cfg.sky:
            raise UserError(f"{args.config} has no [tracker.sky] table: its daemon runs the paper's single-target "
                            "tracker, which has no tracks to pin")
        path = cfg.control_socket_path()
    else:
        raise UserError(f"daemon {args.operator}: give the running daemon's --config FILE.toml (or --socket PATH)")
    if not args.timeout_s > 0:
        raise UserError(f"--timeout-s must be > 0, got {args.timeout_s}")
    request = {"command": args.operator, **({"track_id": args.track_id} if args.operator == "pin" else {})}
    reply = ask_daemon(path, request, args.timeout_s)
    if not reply.get("ok"):
        raise UserError(f"the daemon refused: {reply['message']}")
    print(f"foveatrack daemon: {reply['message']}")
    return 0


def cmd_daemon(args) -> int:
    import json
    import sys

    from foveatrack.daemon import Daemon, load_config
    from foveatrack.errors import UserError

    if args.config is None:
        raise UserError("daemon: --config FILE.toml is required (examples/daemon-virtual.toml)")
    cfg = load_config(args.config)
    from foveatrack.daemon.support import StatusLine

    # stderr in a file on a full disk: what cannot be said is not said, and the daemon runs (and exits
    # with its own code) all the same; a print raised ENOSPC and ended the command with 1
    say = StatusLine(sys.stderr, enabled=False).note
    for w in cfg.warnings():
        say(f"foveatrack daemon: WARNING: {w}")
    if args.check:
        from foveatrack.daemon.runtime import daemon_controller

        # [tracker.sky] is read where the controller is built: --check reads it the same way
        ctl = daemon_controller(cfg, cfg.speed_table())
        sky = {"tracker_sky": ctl.sky_table(), "control_socket": str(cfg.control_socket_path())} if cfg.sky else {}
        print(json.dumps({"lidar": cfg.lidar.__dict__, "head": cfg.head.__dict__,
                          "tracker_overrides": cfg.tracker_overrides, "recording": cfg.recording.__dict__,
                          "daemon": cfg.loop.__dict__, **sky}, indent=1, default=str))
        # the devices as the daemon opens them: a port that does not exist or a socket another process
        # holds fails here, naming the key (before: --check passed a head port that did not exist)
        cfg.check_recording_dir()
        cfg.check_control_socket()
        print(f"foveatrack daemon --check: {check_devices(cfg)}", file=sys.stderr)
        return 0
    if args.duration_s is not None and not args.duration_s > 0:
        raise UserError(f"--duration-s must be > 0, got {args.duration_s}")
    live = None
    if args.live is not None:
        from foveatrack.recording.live import check_port

        live = check_port(args.live)
    elif args.live_origin:
        raise UserError("--live-origin is for the live view: add --live")
    from foveatrack.daemon.heap import return_freed_memory

    # a process that runs for days: freed frames go back to the system (not after a one-shot --check)
    heap_fixed = return_freed_memory()
    d = Daemon(cfg, log_path=args.log, status=False if args.no_status else None, duration_s=args.duration_s,
               live_port=live, live_origins=args.live_origin)
    d.heap_returns_freed = heap_fixed
    code = d.run()
    s = d.final_stats
    timing = (f"processing p99 {s['processing_ms_p99']} ms, latency p99 {s.get('latency_ms_p99', float('nan'))} ms"
              if "processing_ms_p99" in s else "no frame processed")
    # through the daemon's status line: a stderr that failed during the run (ENOSPC) is not written
    # again, and a failure here does not replace the run's exit code
    d.status.note(f"foveatrack daemon: {s.get('frames', 0)} frames, {s.get('frames_detected', 0)} with a "
                  f"detection; {timing}{'; recording ' + str(d.recording_path) if d.recording_path else ''}")
    for problem in d.problems():
        d.status.note(f"foveatrack daemon: {problem}")
    if code == 0 and d.no_lidar_data:
        return NO_LIDAR_DATA_EXIT     # a run that never heard the lidar did not do its job
    return code


NO_LIDAR_DATA_EXIT = 3


def check_devices(cfg) -> str:
    """Open the head's port and bind the lidar's sockets as the daemon does, close them, and say what
    was opened; a UserError naming the key when one cannot be."""
    from foveatrack.live_devices import open_devices

    head, client = open_devices(cfg)
    try:
        ident = head.identity
        ports = f"cmd {client.cmd_port}, data {client.data_port}" + (
            f", broadcast {client.broadcast_port}" if client.broadcast_port is not None else "")
        return (f"head port {cfg.head.port!r} opened"
                + (f" ({ident.describe()})" if ident is not None else "")
                + f"; lidar sockets bound ({ports})")
    finally:
        client.close()
        head.close()
