"""``foveatrack replay RECORDING``: re-run detection and control over a recording, deterministically.

RECORDING is a foveatrack recording (``.mcap``, from the simulator or the daemon) or a Livox Viewer
``.lvx`` file (lidar only, head frozen; it carries no tracker configuration, so ``--tracker-config``
with a space of interest is required).  Prints the metrics (tracking error from truth when the
recording has it, detection bearing errors otherwise), whether the replayed detections and commands
equal the recorded ones, and with ``--tracker-config`` what would have changed.
"""

from __future__ import annotations

import sys


def register(sub) -> None:
    p = sub.add_parser("replay", help="re-run detection and control over a recording (.mcap) or a .lvx file",
                       description="Re-run the recorded tracker (or --tracker-config's) over a recording's frames and "
                                   "say whether its detections and head commands came out identical to the recorded "
                                   "ones; a recording of the multi-object tracker ([tracker.sky]) has every frame's "
                                   "tracks compared too, and the first frame where they differ named.")
    p.add_argument("recording", metavar="RECORDING", help="a foveatrack .mcap recording or a Livox Viewer .lvx")
    p.add_argument("--tracker-config", metavar="FILE.toml",
                   help="use this [tracker] table (a scene, a daemon config or a bare table) instead of the recorded one; "
                        "it must set a space of interest ([tracker.space]); an .lvx needs one")
    p.add_argument("--json", action="store_true", help="print the summary as JSON on stdout")
    p.add_argument("--plot", metavar="DIR", help="write Fig. 14a/b/c equivalents as PNG into DIR (a multi-object recording: "
                                                      "head.png and tracks.png)")
    p.add_argument("--export-points", metavar="F.csv|F.npz", help="export every recorded point")
    p.add_argument("--export-trajectory", metavar="F.csv|F.npz",
                   help="export the replay's per-frame detections, commands, head and world estimates (and truth)")
    p.add_argument("--overwrite", action="store_true", help="replace export files that exist (else refused)")
    p.add_argument("--max-frames", type=int, default=None, metavar="N",
                   help="read at most N frames of a .mcap recording (default: one per 8 bytes of the file, "
                        "at least 10000; a file claiming more is crafted or damaged, and replay says where it stopped)")
    p.add_argument("--live", nargs="?", const=8765, default=None, metavar="PORT",
                   help="first serve the recording to Foxglove (ws://127.0.0.1:PORT, default 8765), paced at --speed")
    p.add_argument("--live-origin", action="append", default=[], metavar="ORIGIN",
                   help="with --live: also let a web page at ORIGIN (scheme://host[:port]; * for any) read the live "
                        "view; by default only clients without an Origin (the Foxglove app, scripts) and Foxglove's "
                        "web app (https://app.foxglove.dev) are served, so another page in a local browser cannot read it")
    # the --live options default to None so that one given without --live is told, not ignored
    p.add_argument("--speed", type=float, default=None, metavar="FACTOR",
                   help="with --live: recorded seconds per wall second (default 1 = as recorded)")
    p.add_argument("--wait-s", type=float, default=None, metavar="S",
                   help="with --live: wait until a viewer connects, at most S seconds, then stream "
                        "(default 3; 0: stream at once)")
    p.add_argument("--linger-s", type=float, default=None, metavar="S",
                   help="with --live: after the last message, keep serving a connected viewer until it "
                        "disconnects, at most S seconds (default 30; 0: close at once)")
    p.set_defaults(func=cmd_replay)


def cmd_replay(args) -> int:
    import json
    from pathlib import Path

    from foveatrack.config_util import check_outputs
    from foveatrack.errors import UserError
    from foveatrack.replay import export_replay_trajectory, format_report, replay

    _check_recording_arg(args.recording)
    if args.tracker_config:
        _check_tracker_config(args.tracker_config)
    # before the replay, which takes a while on a long recording
    check_outputs([("--export-points", args.export_points, (".csv", ".npz")),
                   ("--export-trajectory", args.export_trajectory, (".csv", ".npz"))],
                  inputs=[args.recording], overwrite=args.overwrite)
    live_only = [flag for flag, v in (("--live-origin", args.live_origin), ("--speed", args.speed),
                                      ("--wait-s", args.wait_s), ("--linger-s", args.linger_s)) if v not in (None, [])]
    if args.live is None and live_only:
        raise UserError(f"{', '.join(live_only)}: for the live view only (replay itself runs as fast as it can): "
                        "add --live")
    if args.live is not None and not args.recording.lower().endswith(".lvx"):
        from foveatrack.recording.live import check_port, stream_recording

        speed = 1.0 if args.speed is None else args.speed
        wait_s = 3.0 if args.wait_s is None else max(args.wait_s, 0.0)
        linger_s = 30.0 if args.linger_s is None else max(args.linger_s, 0.0)
        n = stream_recording(args.recording, check_port(args.live), speed, wait_s,
                             say=lambda t: print(t, file=sys.stderr, flush=True), linger_s=linger_s,
                             allowed_origins=args.live_origin)
        print(f"live view: served {n} messages", file=sys.stderr)
    elif args.live is not None:
        raise UserError("--live serves foveatrack recordings (.mcap); a .lvx file has no records to show")
    if args.max_frames is not None and args.max_frames < 1:
        raise UserError(f"--max-frames {args.max_frames}: give a whole number of frames >= 1")
    res = replay(args.recording, args.tracker_config, args.max_frames)
    notes = []
    if args.export_points:
        if res.source == "lvx":
            raise UserError("--export-points reads foveatrack recordings; for a .lvx file use its own tools")
        from foveatrack.recording import export_points

        n = export_points(args.recording, args.export_points, max_frames=args.max_frames)
        notes.append(f"{n} points -> {args.export_points}")
    if args.export_trajectory:
        n = export_replay_trajectory(res, args.export_trajectory)
        notes.append(f"{n} frames -> {args.export_trajectory}")
    if args.plot and not len(res.frames["t_end_s"]):
        # blank axes would read as a run drawn (a user found four empty figures and exit 0)
        notes.append("--plot: no plots, the recording holds no lidar frames")
    elif args.plot:
        from foveatrack.cli.replay_plots import plot_all
        from foveatrack.config_util import output_dir

        out = output_dir(args.plot, "--plot")
        for f in plot_all(res, out):
            notes.append(f"plot -> {f}")
    if args.json:
        s = res.summary()
        s["outputs"] = notes
        print(json.dumps(s, indent=1, default=lambda x: x.item() if hasattr(x, "item") else str(x)))
        damage = res.comparison.get("recording_damage")
        held = res.comparison.get("recording_held")
        if damage:   # stdout is for the machine; a person watching must still see that bytes were skipped
            print(f"foveatrack replay: WARNING: damaged recording, {'; '.join(damage)}", file=sys.stderr)
        if held:     # a writer's or a recover's file: its end is not damage (the text report says the same)
            print(f"foveatrack replay: note: {held}", file=sys.stderr)
        if res.comparison.get("recording_capped"):
            print(f"foveatrack replay: WARNING: {args.recording} read in part: {res.comparison['recording_capped']}",
                  file=sys.stderr)
    else:
        print(format_report(res))
        for n in notes:
            print("  " + n)
    return 0


def _check_recording_arg(recording) -> None:
    """A directory given as RECORDING is a UserError saying so (not "no such recording"), naming
    the newest ``.mcap`` in it when there is one: the likely meant file."""
    from pathlib import Path

    from foveatrack.errors import UserError

    p = Path(recording)
    if not p.is_dir():
        return
    mcaps = [f for f in p.glob("*.mcap") if f.is_file()]
    if mcaps:
        # the newest few with their sizes: the newest alone was once a run stopped before any frame
        newest = sorted(mcaps, key=lambda f: f.stat().st_mtime, reverse=True)[:3]
        listed = ", ".join(f"{f} ({f.stat().st_size / 1e6:.1f} MB)" for f in newest)
        raise UserError(f"{p}: is a directory, not a recording; give a file, e.g. one of the newest "
                        f"recordings in it: {listed} ({len(mcaps)} .mcap file(s) in it)")
    raise UserError(f"{p}: is a directory, not a recording (no .mcap files in it); "
                    "give a .mcap recording or a .lvx file")


def _check_tracker_config(path) -> None:
    """An empty ``--tracker-config`` file (nothing but whitespace or comments) is refused: it would
    be read as "all defaults", which is almost certainly not what was meant (a file saved before it
    was written, a wrong file).  A file that says ``[tracker]`` with nothing under it still means the
    defaults, on purpose."""
    from foveatrack.config_util import read_toml
    from foveatrack.errors import UserError

    data, _ = read_toml(path, "tracker config (--tracker-config)")
    if not data:
        raise UserError(f"--tracker-config {path}: the file is empty (no keys, no tables); give a [tracker] "
                        "table, a scene or a daemon config (an empty [tracker] table means all defaults)")
