"""Exporting a recording's points, trajectory and IMU samples as CSV or NPZ."""

from __future__ import annotations

import csv
import math
import os
from pathlib import Path
from typing import Callable, Iterable

import numpy as np

from foveatrack.atomic_file import written_whole
from foveatrack.errors import UserError
from foveatrack.metrics import flatten
from foveatrack.recording.format import COMMANDS, DETECTIONS, HEAD, IMU, POINTS, TRACKS, TRUTH, TRUTH_OBJECTS
from foveatrack.recording.reader import RecordingReader
from foveatrack.recording.segments import open_run


def out_kind(out_path: Path) -> str:
    """"csv" or "npz", from the file name; any other is an error that names the file."""
    suf = out_path.suffix.lower()
    if suf not in (".csv", ".npz"):
        raise UserError(f"export to {out_path}: the file name must end in .csv or .npz")
    return suf[1:]


def write_columns(out_path: Path, cols: dict, nan_as_empty: bool = False) -> None:
    """Equal-length columns as NPZ (one array each) or CSV (a header row, then a row per index), by
    the file name; ``nan_as_empty``: a NaN is an empty CSV cell.  The file appears under its name
    only when it is whole (:func:`~foveatrack.atomic_file.written_whole`)."""
    if out_kind(out_path) == "npz":
        _write_npz(out_path, cols)
        return
    arrays = [np.asarray(c) for c in cols.values()]
    with written_whole(out_path) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(cols.keys())
        if len(arrays) > 1 and all(a.ndim == 1 and a.dtype.kind in "biuf" for a in arrays):
            _write_numeric_rows(fh, arrays, nan_as_empty)
            return
        for row in zip(*(a.tolist() for a in arrays)):
            w.writerow(["" if nan_as_empty and isinstance(v, float) and math.isnan(v) else v for v in row])


def _write_npz(out_path: Path, arrays: dict) -> None:
    """``arrays`` as a compressed NPZ, under ``out_path`` only when whole (given a file, not a name:
    numpy would add ".npz" to the temporary's)."""
    with written_whole(out_path) as tmp, open(tmp, "wb") as fh:
        np.savez_compressed(fh, **arrays)


_CSV_BLOCK_ROWS = 65536


def _write_numeric_rows(fh, arrays: list, nan_as_empty: bool) -> None:
    """The rows csv.writer writes for numeric columns (str of each Python number, no quoting needed,
    \r\n), built a block of rows at a time: csv.writer's row-by-row calls took 4 s for 117 000
    points (slower than a Mid-40 makes them)."""
    n = len(arrays[0])
    for start in range(0, n, _CSV_BLOCK_ROWS):
        cells = []
        for a in arrays:
            col = list(map(str, a[start:start + _CSV_BLOCK_ROWS].tolist()))
            if nan_as_empty and a.dtype.kind == "f":
                col = ["" if c == "nan" else c for c in col]
            cells.append(col)
        fh.write("".join(",".join(row) + "\r\n" for row in zip(*cells)))


Warn = Callable[[str], None]


def _warn_damage(reader: RecordingReader, warn: Warn | None) -> None:
    """Tell ``warn`` what the reader skipped (the line ``replay`` prints), once the whole file was read."""
    line = reader.warning()
    if line is not None and warn is not None:
        warn(line)


def export_points(recording: str | os.PathLike, out_path: str | os.PathLike, warn: Warn | None = None,
                  max_frames: int | None = None) -> int:
    """Write all recorded points to CSV or NPZ (by suffix); returns the number of points.

    Columns / arrays: frame_index, frame_t_ns, t_ns, x_m, y_m, z_m, reflectivity (lidar frame).
    ``warn`` gets the one-line warning of a damaged recording (what was skipped and lost) or of one
    read in part (``max_frames``: the cap on frames, default the reader's for the file's size).
    """
    out_path = Path(out_path)
    out_kind(out_path)
    reader = open_run(recording, max_frames, segment_alone=True)
    frames = list(reader.points())
    _warn_damage(reader, warn)
    if frames:
        cols = {
            "frame_index": np.concatenate([np.full(len(f), f.frame_index, np.int64) for f in frames]),
            "frame_t_ns": np.concatenate([np.full(len(f), f.t_ns, np.int64) for f in frames]),
            "t_ns": np.concatenate([f.t_ns_points for f in frames]),
            "x_m": np.concatenate([f.xyz[:, 0] for f in frames]),
            "y_m": np.concatenate([f.xyz[:, 1] for f in frames]),
            "z_m": np.concatenate([f.xyz[:, 2] for f in frames]),
            "reflectivity": np.concatenate([f.reflectivity for f in frames]),
        }
    else:
        cols = {k: np.zeros(0) for k in ("frame_index", "frame_t_ns", "t_ns", "x_m", "y_m", "z_m", "reflectivity")}
    write_columns(out_path, cols)
    return len(cols["t_ns"])


def export_trajectory(
    recording: str | os.PathLike,
    out_path: str | os.PathLike,
    channels: Iterable[str] = (DETECTIONS, HEAD, TRUTH, COMMANDS),
    warn: Warn | None = None,
    max_frames: int | None = None,
) -> int:
    """Write the time series of ``channels`` to CSV or NPZ (by suffix); returns the row count.

    Records are flattened (``xyz_m`` → ``xyz_m[0..2]``, nested dicts → ``a.b``).  CSV: one row per
    record with columns ``channel, t_ns`` and the union of the fields (blank where absent).  NPZ: one
    array per ``<channel>.<field>`` (NaN / "" where a record lacks the field).
    """
    out_path = Path(out_path)
    kind = out_kind(out_path)
    channels = tuple(channels)
    arrays_not_records = {POINTS: "export_points", IMU: "export_imu"}
    for ch in channels:
        if ch in arrays_not_records:
            raise UserError(f"export of channel {ch!r}: its messages are arrays, not records; "
                            f"use {arrays_not_records[ch]}")
    reader = open_run(recording, max_frames, segment_alone=True)
    rows = [(m.channel, flatten(m.record, lists=True)) for m in reader.messages(channels)]
    _warn_damage(reader, warn)
    if kind == "csv":
        keys: list[str] = []
        for _, r in rows:
            keys.extend(k for k in r if k not in keys)
        # a list field is its columns k[0], k[1], ...; where it was null it also came as k, a column
        # that was blank in every row (xyz_m, world_xyz_m)
        keys = ["t_ns"] + [k for k in keys if k != "t_ns" and f"{k}[0]" not in keys]
        with written_whole(out_path) as tmp, open(tmp, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["channel", *keys])
            for ch, r in rows:
                w.writerow([ch, *("" if r.get(k) is None else r.get(k) for k in keys)])
    else:
        arrays: dict[str, np.ndarray] = {}
        for ch in channels:
            recs = [r for c, r in rows if c == ch]
            keys = []
            for r in recs:
                keys.extend(k for k in r if k not in keys)
            for k in [k for k in keys if f"{k}[0]" not in keys]:     # (a null list: see the CSV above)
                vals = [r.get(k) for r in recs]
                if all(isinstance(v, (int, float, bool)) for v in vals):
                    arrays[f"{ch}.{k}"] = np.array(vals)
                elif all(isinstance(v, (int, float, bool)) or v is None for v in vals):
                    arrays[f"{ch}.{k}"] = np.array([np.nan if v is None else v for v in vals], dtype=float)
                else:
                    arrays[f"{ch}.{k}"] = np.array(["" if v is None else str(v) for v in vals])
        _write_npz(out_path, arrays)
    return len(rows)


def export_imu(recording: str | os.PathLike, out_path: str | os.PathLike, warn: Warn | None = None,
               max_frames: int | None = None) -> int:
    """Write the IMU samples fed to the tracker (the ``imu`` channel) to CSV or NPZ (by suffix);
    returns the sample count.  Columns: ``frame_index`` (the frame they were fed before), ``t_s`` [s]
    as fed, ``gyro_{x,y,z}_rad_s``, and ``accel_{x,y,z}_g`` where the source has an accelerometer
    (NaN, an empty CSV cell, for samples without).  A recording without the channel is an error
    that says so (recordings of runs without an IMU, or made before the channel existed)."""
    out_path = Path(out_path)
    out_kind(out_path)
    cols = imu_columns(recording, warn, max_frames)
    write_columns(out_path, cols, nan_as_empty=True)
    return int(cols["t_s"].shape[0])


def imu_columns(recording: str | os.PathLike, warn: Warn | None = None, max_frames: int | None = None) -> dict:
    """The columns :func:`export_imu` writes, read and checked before anything is written."""
    reader = open_run(recording, max_frames, segment_alone=True)
    batches = list(reader.imu())
    _warn_damage(reader, warn)
    if not batches:
        raise UserError(f"{recording} holds no IMU samples (a run without an IMU on the head, or a recording "
                        f"made before foveatrack recorded them)")
    n = [len(b) for b in batches]
    acc = [b.accel_g if b.accel_g is not None else np.full((len(b), 3), np.nan) for b in batches]
    gyro = np.concatenate([b.gyro_rad_s.reshape(-1, 3) for b in batches])
    accel = np.concatenate([a.reshape(-1, 3) for a in acc])
    cols = {"frame_index": np.repeat([b.frame_id for b in batches], n).astype(np.int64),
            "t_s": np.concatenate([b.t_s for b in batches])}
    cols.update((f"gyro_{a}_rad_s", gyro[:, i]) for i, a in enumerate("xyz"))
    if not np.isnan(accel).all():
        cols.update((f"accel_{a}_g", accel[:, i]) for i, a in enumerate("xyz"))
    return cols


def export_tracks(recording: str | os.PathLike, out_path: str | os.PathLike, warn: Warn | None = None,
                  max_frames: int | None = None) -> int:
    """Write every track of the multi-object tracker, frame by frame (the ``tracks`` channel), to CSV
    or NPZ (by suffix): one row per track and frame, what a multi-object evaluation (CLEAR MOT, GOSPA,
    HOTA) takes beside :func:`export_truth_objects`.  Columns: ``t_ns`` (the frame's end),
    ``frame_id``, ``id``, ``confirmed``, ``label`` (after the classifier's wait), ``looks_like`` (this
    frame), ``x_m, y_m, z_m`` and ``vx_m_s, vy_m_s, vz_m_s`` (world frame), ``hit`` (this frame),
    ``in_view``, ``score`` (the threat score of a confirmed track; empty otherwise), ``fixated`` (the
    fovea served it this frame), ``pinned``.  Returns the row count; a recording of the single-target
    tracker has no tracks and is an error that says so."""
    out_kind(Path(out_path))
    cols = tracks_columns(recording, warn, max_frames)
    write_columns(Path(out_path), cols, nan_as_empty=True)
    return int(cols["id"].shape[0])


def tracks_columns(recording: str | os.PathLike, warn: Warn | None = None, max_frames: int | None = None) -> dict:
    """The columns :func:`export_tracks` writes, read and checked before anything is written."""
    from foveatrack.recording.records import TracksRecord

    frames = _channel_records(recording, TRACKS, TracksRecord.from_json, warn, max_frames,
                              "holds no tracks: a run of the single-target tracker (its detections are in "
                              "--trajectory); the multi-object tracker runs with a [tracker.sky] table")
    rows = [(f, e) for f in frames for e in f.tracks]
    cols = {"t_ns": np.array([f.t_ns for f, _ in rows], dtype=np.int64),
            "frame_id": np.array([f.frame_id for f, _ in rows], dtype=np.int64),
            "id": np.array([e.id for _, e in rows], dtype=np.int64),
            "confirmed": np.array([e.confirmed for _, e in rows], dtype=bool),
            "label": np.array([e.label for _, e in rows]),
            "looks_like": np.array([e.looks_like for _, e in rows])}
    cols.update(_world_columns([e.xyz_m for _, e in rows], [e.velocity_m_s for _, e in rows]))
    cols.update(hit=np.array([e.hit for _, e in rows], dtype=bool),
                in_view=np.array([e.in_view for _, e in rows], dtype=bool),
                score=np.array([math.nan if e.score is None else e.score for _, e in rows], dtype=float),
                fixated=np.array([e.id == f.fixated for f, e in rows], dtype=bool),
                pinned=np.array([e.id == f.pinned for f, e in rows], dtype=bool))
    return cols


def export_truth_objects(recording: str | os.PathLike, out_path: str | os.PathLike, warn: Warn | None = None,
                         max_frames: int | None = None) -> int:
    """Write the simulator's truth of every object of a multi-object scene, frame by frame (the
    ``truth_objects`` channel), to CSV or NPZ (by suffix): ``t_ns`` (the frame's end), ``frame_id``,
    ``id``, ``class`` (drone, bird, tree, clutter: a stray near return), ``x_m, y_m, z_m`` and ``vx_m_s,
    vy_m_s, vz_m_s`` (world frame, at the frame's mid time), ``size_m``, ``rays_hit`` (the frame's rays
    on it, before the effects).  Returns the row count; a recording without the channel (a daemon's,
    a single-target scene's: its one target's truth is in --trajectory) is an error that says so."""
    out_kind(Path(out_path))
    cols = truth_objects_columns(recording, warn, max_frames)
    write_columns(Path(out_path), cols, nan_as_empty=True)
    return int(cols["id"].shape[0])


def truth_objects_columns(recording: str | os.PathLike, warn: Warn | None = None,
                          max_frames: int | None = None) -> dict:
    """The columns :func:`export_truth_objects` writes, read and checked before anything is written."""
    from foveatrack.recording.records import ObjectTruthRecord

    recs = _channel_records(recording, TRUTH_OBJECTS, ObjectTruthRecord.from_json, warn, max_frames,
                            "holds no object truth: only the simulator's runs of multi-object scenes record it "
                            "(a single target's truth is in --trajectory; a daemon knows no truth)")
    cols = {"t_ns": np.array([r.t_ns for r in recs], dtype=np.int64),
            "frame_id": np.array([r.frame_id for r in recs], dtype=np.int64),
            "id": np.array([r.id for r in recs]),
            "class": np.array([r.cls for r in recs])}
    cols.update(_world_columns([r.true_world_m for r in recs], [r.true_velocity_m_s for r in recs]))
    cols.update(size_m=np.array([r.size_m for r in recs], dtype=float),
                rays_hit=np.array([r.rays_hit for r in recs], dtype=np.int64))
    return cols


def _channel_records(recording, channel: str, parse, warn: Warn | None, max_frames: int | None,
                     none_held: str) -> list:
    """The parsed records of one channel; a record whose fields are not of their type is an error
    naming the file, the channel and its time (as replay names it), none an error that says
    ``none_held`` of the recording."""
    from foveatrack.recording.records import RecordError

    reader = open_run(recording, max_frames, segment_alone=True)
    recs = []
    for m in reader.messages(channel):
        try:
            recs.append(parse(m.record))
        except (RecordError, ValueError, TypeError, KeyError) as exc:
            raise UserError(f"{recording}: a {channel} record at time {m.t_ns} ns is damaged: {exc}") from None
    _warn_damage(reader, warn)
    if not recs:
        raise UserError(f"{recording} {none_held}")
    return recs


def _world_columns(xyz: list, velocity: list) -> dict:
    """``x_m, y_m, z_m, vx_m_s, vy_m_s, vz_m_s`` from per-row world positions and velocities."""
    p = np.array(xyz, dtype=float).reshape(-1, 3)
    v = np.array(velocity, dtype=float).reshape(-1, 3)
    cols = {f"{a}_m": p[:, i].copy() for i, a in enumerate("xyz")}
    cols.update((f"v{a}_m_s", v[:, i].copy()) for i, a in enumerate("xyz"))
    return cols

