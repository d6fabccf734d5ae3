"""``foveatrack export RECORDING``: a recording's points as Livox ``.lvx``, CSV or NPZ.

``--lvx OUT`` writes a Livox Viewer LVX v1.1 file (:mod:`foveatrack.livox.lvx_export`) that Livox
Viewer, the vendor SDK's tools and ``livox-lvx`` read; ``--csv`` / ``--npz`` write every point
(:func:`foveatrack.recording.export_points`); ``--trajectory F.csv|F.npz`` the recorded detections,
head, truth and commands (:func:`foveatrack.recording.export_trajectory`); ``--imu F.csv|F.npz`` the IMU
samples fed to the tracker (:func:`foveatrack.recording.export_imu`); ``--tracks F.csv|F.npz`` every track
of the multi-object tracker per frame, and ``--truth-objects F.csv|F.npz`` the simulator's truth of every
object, per frame (:func:`foveatrack.recording.export_tracks`, :func:`~foveatrack.recording.
export_truth_objects`: what a multi-object evaluation takes).  Several at once are fine.

A damaged recording is exported from everything the reader recovered, and ``export`` prints on stderr
the warning ``replay`` prints: the bytes skipped and the frames and records lost with them.
"""

from __future__ import annotations


def register(sub) -> None:
    p = sub.add_parser("export", help="write a recording's points as Livox .lvx, CSV or NPZ")
    p.add_argument("recording", metavar="RECORDING", help="a foveatrack .mcap recording")
    p.add_argument("--lvx", metavar="OUT.lvx", help="Livox Viewer LVX v1.1 file of every point")
    p.add_argument("--csv", metavar="OUT.csv", help="every point as CSV")
    p.add_argument("--npz", metavar="OUT.npz", help="every point as NPZ")
    p.add_argument("--trajectory", metavar="F.csv|F.npz", help="detections, head, truth and commands over time")
    p.add_argument("--imu", metavar="F.csv|F.npz", help="the IMU samples fed to the tracker (gyro, accel)")
    p.add_argument("--tracks", metavar="F.csv|F.npz",
                   help="every track of the multi-object tracker ([tracker.sky]), a row per track and frame")
    p.add_argument("--truth-objects", metavar="F.csv|F.npz",
                   help="the simulator's truth of every object of a multi-object scene, a row per object and frame")
    p.add_argument("--data-type", type=int, metavar="N",
                   help="LVX point data type: 0 Cartesian, 1 spherical, 2/3 extended, 4/5 dual, 7/8 triple "
                        "(default: what the device sends, Mid-40 0, others 2)")
    p.add_argument("--device", metavar="NAME",
                   help="LVX device (mid40, horizon, tele15, mid70, avia, mid100); default: the recording's preset")
    p.add_argument("--max-frames", type=int, default=None, metavar="N",
                   help="read at most N frames (default: one per 8 bytes of the file, at least 10000; a file "
                        "claiming more is crafted or damaged, and export warns where it stopped)")
    p.add_argument("--frame-ms", type=int, default=50, metavar="MS", help="LVX frame length (default 50, as Livox Viewer)")
    p.add_argument("--overwrite", action="store_true", help="replace output files that exist (else refused)")
    p.set_defaults(func=cmd_export)


def cmd_export(args) -> int:
    import sys
    from pathlib import Path

    from foveatrack.config_util import check_outputs
    from foveatrack.errors import UserError
    from foveatrack.recording.format import MCAP_MAGIC

    said: set[str] = set()

    def warn(line: str | None) -> None:
        """What a damaged recording lost, as ``replay`` says it: once, however many files are written."""
        if line and line not in said:
            said.add(line)
            print(line, file=sys.stderr, flush=True)

    outs = [("--lvx", args.lvx, (".lvx",)), ("--csv", args.csv, (".csv",)), ("--npz", args.npz, (".npz",)),
            ("--trajectory", args.trajectory, (".csv", ".npz")), ("--imu", args.imu, (".csv", ".npz")),
            ("--tracks", args.tracks, (".csv", ".npz")), ("--truth-objects", args.truth_objects, (".csv", ".npz"))]
    if not any(path for _, path, _ in outs):
        raise UserError("export: give at least one of " + ", ".join(flag for flag, _, _ in outs))
    rec = Path(args.recording)
    if rec.is_dir():
        raise UserError(f"{rec} is a directory; give the recording inside it (e.g. {rec / 'run.mcap'})")
    if not rec.is_file():
        raise UserError(f"{rec}: no such recording")
    from foveatrack.recording.reader import read_head

    head = read_head(rec, 10)
    if head == b"livox_tech":
        raise UserError(f"{rec} is already a Livox .lvx file; export reads foveatrack .mcap recordings")
    if rec.suffix.lower() == ".lvx" and not head.startswith(MCAP_MAGIC):
        # named .lvx but not one: its LVX header's problem, not "no MCAP magic"
        from foveatrack.livox.lvx import LvxReader

        LvxReader(rec).close()
    check_outputs(outs, inputs=[rec], overwrite=args.overwrite)
    if args.max_frames is not None and args.max_frames < 1:
        raise UserError(f"--max-frames {args.max_frames}: give a whole number of frames >= 1")
    cap = args.max_frames
    if args.data_type is not None or args.device:
        if not args.lvx:
            raise UserError("--data-type and --device are for --lvx")
    from foveatrack.recording import export_points, export_trajectory
    from foveatrack.recording.export import imu_columns, tracks_columns, truth_objects_columns, write_columns

    # the tables a recording may lack (IMU samples, the multi-object tracker's tracks, the objects'
    # truth) are read and checked first: a recording without one is an error, and it must come
    # before any output is written (the IMU came last once, after the points had been written; then
    # the IMU table was written before the tracks were found missing)
    tables = [(path, read(rec, warn, cap), what) for path, read, what in (
        (args.imu, imu_columns, "IMU samples"), (args.tracks, tracks_columns, "track rows"),
        (args.truth_objects, truth_objects_columns, "object truth rows")) if path]
    if args.lvx:
        from foveatrack.livox.lvx_export import export_lvx

        r = export_lvx(rec, args.lvx, data_type=args.data_type, device=args.device, frame_duration_ms=args.frame_ms,
                       max_frames=cap)
        extra = ""
        if r.time_gaps:
            extra += f"; {r.time_gaps} gap(s) in the point times over 1 s (a sensor clock jump?) not filled with frames"
        print(f"{r.points} points in {r.packets} packets (data type {r.data_type}, device type {r.device_type}, "
              f"{r.devices} device{'s' if r.devices > 1 else ''}), {r.frames} frames -> {args.lvx}{extra}")
        if r.slot_collisions:
            # points lost from the export: a line of its own, not a clause of a line that reads as success
            # (a track --record recording, whose points share times, lost 286 of 304 so)
            warn(f"WARNING: {args.lvx}: {r.slot_collisions} of the recording's {r.points + r.slot_collisions} points "
                 f"were left out: they share a scan slot (the same time) with another point, and a Livox packet "
                 f"holds one return a slot")
        if r.guessed:
            warn(f"note: {args.lvx}: {r.guessed}")
        warn(r.problem)

    for flag, path in (("--csv", args.csv), ("--npz", args.npz)):
        if path:
            print(f"{export_points(rec, path, warn=warn, max_frames=cap)} points -> {path}")
    if args.trajectory:
        print(f"{export_trajectory(rec, args.trajectory, warn=warn, max_frames=cap)} records -> {args.trajectory}")
    for path, cols, what in tables:
        write_columns(Path(path), cols, nan_as_empty=True)
        print(f"{len(next(iter(cols.values())))} {what} -> {path}")
    return 0
