"""``foveatrack track SOURCE``: track a drone in a recording someone else made with a fixed lidar.

SOURCE is a ROS 1 bag (``.bag``), a ROS 2 bag (its folder, or the ``.mcap`` / ``.db3`` file), a
folder of PCD files or a folder of ``<unix time>.npy`` frames (:mod:`foveatrack.sources`).  The
drone is acquired without a hand-made D (:mod:`foveatrack.openloop.tracker`), or with one given by
``--box`` or an ``[openloop]`` table's ``space``.  Prints the figures; writes the track's CSV, PNG
plots, and with ``--reference`` the error against a reference trajectory per frame and in summary.
"""

from __future__ import annotations

import sys


def register(sub) -> None:
    p = sub.add_parser("track", help="track a drone in a ROS bag, PCD or numpy frame folder from a fixed lidar")
    p.add_argument("source", metavar="SOURCE",
                   help="a .bag, a ROS 2 bag folder or .mcap/.db3, a folder of <unix time>.npy or .pcd frames")
    p.add_argument("--topic", help="the bag's point-cloud topic (default: its only one; with several, they are listed)")
    p.add_argument("--fixed-frame", metavar="FRAME",
                   help="a bag's clouds turned into this frame with its /tf (a sensor that moved while recording)")
    p.add_argument("--rate-hz", type=float, default=10.0, metavar="HZ",
                   help="the lidar's frame rate (frame length for points without times; default 10)")
    p.add_argument("--config", metavar="FILE.toml", help="an [openloop] table (acquisition and tracking parameters)")
    p.add_argument("--box", type=float, nargs=6, metavar=("X0", "Y0", "Z0", "X1", "Y1", "Z1"),
                   help="a hand-made space of interest D [m, sensor frame]: no acquisition, Algorithm 1 in it")
    p.add_argument("--reference", metavar="CSV|DIR",
                   help="a reference trajectory: CSV of time,x,y,z or a folder of <unix time>.npy estimates")
    p.add_argument("--csv", metavar="F.csv", help="write the track (one row per frame)")
    p.add_argument("--plot", metavar="DIR", help="write PNG plots into DIR")
    p.add_argument("--record", metavar="F.mcap",
                   help="write a Foxglove recording: the cloud, the track and the D of every frame")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument("--overwrite", action="store_true", help="replace a --csv or --record file that exists (else refused)")
    p.set_defaults(func=cmd_track)


def cmd_track(args) -> int:
    import json

    from foveatrack.config_util import check_outputs, read_toml
    from foveatrack.errors import UserError
    from foveatrack.openloop import OpenLoopConfig, track_source
    from foveatrack.openloop.reference import load_reference
    from foveatrack.sources import open_source

    # never one of the scans it reads (a --csv named after a scan replaced it), nor a file that exists
    check_outputs([("--csv", args.csv, (".csv",)), ("--record", args.record, (".mcap",))], inputs=[args.source],
                  overwrite=args.overwrite)
    if args.record:
        from foveatrack.openloop.recording import check_frame_length

        check_frame_length(args.rate_hz, args.record)
    cfg = OpenLoopConfig()
    if args.config:
        data, _ = read_toml(args.config, "open-loop config (--config)")
        _refuse_other_tables(args.config, data)
        table = data.get("openloop", data)
        cfg = OpenLoopConfig.from_mapping(table, f"{args.config} [openloop]")
    if args.box:
        from dataclasses import replace

        from foveatrack.space_of_interest import Box

        try:
            box = Box(tuple(args.box[:3]), tuple(args.box[3:]))
        except UserError as exc:
            raise UserError(f"--box: {exc}") from None
        cfg = replace(cfg, space=box)
    reference = load_reference(args.reference) if args.reference else None
    source = open_source(args.source, args.topic, args.rate_hz, args.fixed_frame)
    from tqdm import tqdm

    bar = tqdm(total=len(source) if hasattr(source, "__len__") else None, desc="tracking", unit=" frame",
               file=sys.stderr, leave=False, disable=None)
    recorder = None
    notes = []
    try:
        if args.record:
            from foveatrack.openloop.recording import TrackRecorder

            recorder = TrackRecorder(args.record, {"input": str(args.source), "topic": args.topic},
                                     overwrite=args.overwrite)
        res = track_source(source, cfg, reference, progress=lambda k: bar.update(1), observer=recorder)
    finally:
        bar.close()
        if recorder is not None:
            recorder.close()   # what was recorded stays readable when a frame further on is bad
    if recorder is not None:
        notes.append(f"{recorder.writer.frames_written} frames -> {args.record} (Foxglove)")
    if args.csv:
        from foveatrack.openloop.run import write_track_csv

        n = write_track_csv(res, args.csv)
        notes.append(f"{n} frames -> {args.csv}")
    if args.plot:
        from foveatrack.cli.track_plots import plot_all
        from foveatrack.config_util import output_dir

        out = output_dir(args.plot, "--plot")
        for f in plot_all(res, out):
            notes.append(f"plot -> {f}")
    if args.json:
        s = dict(res.summary, source=res.source, path=res.path, outputs=notes)
        print(json.dumps(s, indent=1))
    else:
        print(format_summary(res))
        for n in notes:
            print("  " + n)
    return 0


def format_summary(res) -> str:
    s = res.summary
    lines = [f"foveatrack track: {res.path} ({res.source})",
             f"  frames {s['frames']}, tracked {s['frames_tracked']}"
             + ("  (D given by hand: no acquisition)" if s["d_given"] else "")]
    t0 = s.get("first_frame_s")
    for c in s["confirmed"]:
        lines.append(f"  confirmed track {c['track_id']}: first seen {c['first_seen_s'] - t0:.2f} s, confirmed "
                     f"{c['confirmed_s'] - t0:.2f} s after the first frame, {c['hits']} hits, "
                     f"mean range {c['mean_range_m']:.1f} m")
    if not s["d_given"] and not s["confirmed"]:
        lines.append("  no confirmed track")
    ref = s.get("reference")
    if ref:
        e = ref["error"]
        if e["frames"]:
            lines.append(f"  distance to the reference over {e['frames']} tracked frames: median {e['median_m']:.3f} m, "
                         f"p95 {e['p95_m']:.3f} m, max {e['max_m']:.3f} m "
                         f"({ref['frames_with_reference']} frames have a reference sample)")
        else:
            lines.append(f"  no tracked frame has a reference sample ({ref['frames_with_reference']} frames have one)"
                         + _why_no_reference(ref))
        if ref.get("matched_at"):
            lines.append(f"  the reference was sampled at {ref['matched_at']}")
    return "\n".join(lines)


def _why_no_reference(ref: dict) -> str:
    """Why no tracked frame met a reference sample: the reference's time span and the tracked frames'
    (the frames', if none was tracked), and whether they overlap at all -- a reference in seconds from
    its start against frames in unix seconds, or in ns against seconds, never does."""
    import math

    r, f, who = ref.get("t_range_s"), ref.get("tracked_t_range_s"), "tracked frames"
    if f is None:
        f, who = ref.get("frames_t_range_s"), "frames"
    if r is None or f is None:
        return ""

    def t(v):
        return f"{v:.3f}" if abs(v) < 1e11 else f"{v:.6g}"

    text = f": the reference spans {t(r[0])} .. {t(r[1])} s, the {who} {t(f[0])} .. {t(f[1])} s"
    if r[0] <= f[1] and f[0] <= r[1]:
        if ref["frames_with_reference"]:       # the frames that have one were not tracked
            return text
        return text + (f"; no reference sample lies within {ref['max_dt_s'] * 1e3:.0f} ms (half a frame) of a "
                       f"{who[:-1]}'s time")
    text += "; they do not overlap"
    unix = 1e8                       # 1973 in unix seconds: a time below it is counted from a recording's start
    if r[1] < unix <= f[0]:
        return text + (" (the reference's times look like seconds from its start, the frames' like unix seconds: "
                       "give the reference in unix seconds)")
    if f[1] < unix <= r[0]:
        return text + " (the frames' times look like seconds from their start, the reference's like unix seconds)"
    if unix <= f[0] and r[0] > 0:
        unit = {3: "ms", 6: "µs", 9: "ns"}.get(3 * round(math.log10(r[0] / f[0]) / 3))
        if unit:
            return text + f" (the reference's times look like {unit} since 1970; --reference takes seconds)"
    return text


def _refuse_other_tables(path: str, data: dict) -> None:
    """``--config`` holds the open-loop tracker's keys, in an ``[openloop]`` table or bare; a file with
    other tables (a scene, a daemon config, a ``[tracker.sky]`` table) would have them ignored, or be
    told of an ``[openloop]`` table it does not have."""
    from dataclasses import fields

    from foveatrack.errors import UserError
    from foveatrack.openloop import OpenLoopConfig

    known = {f.name for f in fields(OpenLoopConfig)}
    def is_table(v) -> bool:
        return isinstance(v, dict) or (isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v))

    others = sorted(k for k, v in data.items() if k != "openloop" and is_table(v)
                    and ("openloop" in data or k not in known))
    if not others:
        return
    sky = isinstance(data.get("tracker"), dict) and "sky" in data["tracker"]
    why = (": the multi-object tracker ([tracker.sky]) runs in simulate, replay and the daemon; `track` "
           "follows one drone with the open-loop tracker" if sky else "")
    raise UserError(f"{path}: `track --config` reads an [openloop] table (docs/real-recordings.md), and "
                    f"this file has {', '.join(f'[{k}]' for k in others)}{why}")

