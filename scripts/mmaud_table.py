"""MMAUD (CVPR 2024 UG2+ anti-UAV challenge) through ``foveatrack track``: the table of
docs/real-recordings.md.  Fetches nothing: give it the folder of the dataset's published sequences.

The folder is the repository ``dtc111111/Multi-Modal-UAV`` (MIT), or its ``point_cloud_processing``
folder: ``val/seqN/livox_avia/<unix time>.npy`` (Livox Avia frames) and ``result/seqN/<unix time>.npy``
(one estimate per frame by a challenge team -- their estimate, not the ground truth).  For every
sequence found it runs the open-loop tracker without a hand-made D (:mod:`foveatrack.openloop`) and
prints: when the drone was acquired after its first frame with at least 5 returns, the frames it was
tracked in while in the field, the median and p95 distance to the team's estimates, and the
confirmed tracks on the stray sky returns.

"A drone return" is a point within 0.5 m of the team's estimate for that frame: the table's own
yardstick for where the drone was (the tracker does not use the estimates).  "Stray sky returns"
are the points beyond 20 m (the drone flies at about 2 m; the sky gives single returns at 100-400 m);
a confirmed track whose mean range is beyond 20 m is one on them.

Usage: python scripts/mmaud_table.py MMAUD_DIR [--sensor livox_avia] [--docs docs/real-recordings.md]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

from foveatrack.environment import describe
from foveatrack.errors import UserError
from foveatrack.openloop import OpenLoopConfig, track_source
from foveatrack.openloop.reference import load_reference, match_reference
from foveatrack.sources import open_source

DRONE_RADIUS_M = 0.5
SKY_RANGE_M = 20.0


def find_root(folder: Path) -> Path:
    for cand in (folder, folder / "point_cloud_processing"):
        if (cand / "val").is_dir() and (cand / "result").is_dir():
            return cand
    raise UserError(f"{folder}: no val/ and result/ folders (give the Multi-Modal-UAV repository or its "
                    "point_cloud_processing folder)")


def run_sequence(root: Path, seq: str, sensor: str, plot_dir: Path | None = None) -> dict:
    src_dir = root / "val" / seq / sensor
    ref = load_reference(root / "result" / seq)
    frames = [fr for _, fr in open_source(src_dir)]
    load0 = os.getloadavg()[0]
    t0, c0 = time.perf_counter(), time.process_time()
    res = track_source(open_source(src_dir), OpenLoopConfig(), reference=ref)
    wall_s, cpu_s = time.perf_counter() - t0, time.process_time() - c0
    f = res.frames
    idx = match_reference(f["t_s"], ref[0], 0.05)
    drone_n = np.zeros(len(frames), int)
    sky_n = np.zeros(len(frames), int)
    for k, fr in enumerate(frames):
        r = np.linalg.norm(fr.xyz, axis=1)
        sky_n[k] = int(np.sum(r > SKY_RANGE_M))
        if idx[k] >= 0:
            drone_n[k] = int(np.sum(np.linalg.norm(fr.xyz - ref[1][idx[k]], axis=1) < DRONE_RADIUS_M))
    first5 = int(np.argmax(drone_n >= 5)) if np.any(drone_n >= 5) else None
    drone_tracks = [c for c in res.confirmed if c["mean_range_m"] <= SKY_RANGE_M and not c["static"]]
    sky_tracks = [c for c in res.confirmed if c["mean_range_m"] > SKY_RANGE_M]
    acq = None
    if first5 is not None and drone_tracks:
        acq = drone_tracks[0]["confirmed_s"] - f["t_s"][first5]
    k_acq = int(np.argmax(f["detected"])) if f["detected"].any() else len(frames)
    in_field = np.flatnonzero(drone_n > 0)
    in_field_after = in_field[in_field >= k_acq]
    e = res.summary["reference"]["error"]
    plots = []
    if plot_dir is not None:
        from foveatrack.cli.track_plots import plot_all

        out = plot_dir / f"{seq}-{sensor}"
        out.mkdir(parents=True, exist_ok=True)
        plots = plot_all(res, out)
    return {"plots": plots, "seq": seq, "sensor": sensor, "frames": len(frames), "drone_frames": int(in_field.size),
            "first5_s": None if first5 is None else float(f["t_s"][first5] - f["t_s"][0]),
            "first5_returns": None if first5 is None else int(drone_n[first5]),
            "acquired_s": acq, "tracked": int(f["detected"].sum()),
            "tracked_in_field": int(f["detected"][in_field_after].sum()), "in_field_after": int(in_field_after.size),
            "tracked_outside_field": int(np.sum(f["detected"] & (idx >= 0) & (drone_n == 0))),
            "median_m": e["median_m"], "p95_m": e["p95_m"], "max_m": e["max_m"], "err_frames": e["frames"],
            "sky_points": int(sky_n.sum()), "sky_frames": int(np.sum(sky_n > 0)),
            "sky_tracks": len(sky_tracks), "confirmed": len(res.confirmed),
            "wall_s": wall_s, "cpu_s": cpu_s, "load": load0}


def table(rows: list[dict]) -> str:
    out = ["| sequence | frames | first frame with >= 5 drone returns | acquired (no D) after it | "
           "frames tracked in the field | median / p95 / max distance to the team's estimates | "
           "returns beyond 20 m | confirmed tracks beyond 20 m | confirmed tracks in all |",
           "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        acq = "not acquired" if r["acquired_s"] is None else f"{r['acquired_s']:.2f} s"
        first = "none" if r["first5_s"] is None else f"{r['first5_s']:.2f} s ({r['first5_returns']} returns)"
        med = "-" if r["median_m"] is None else (f"{100 * r['median_m']:.1f} / {100 * r['p95_m']:.1f} / "
                                                 f"{100 * r['max_m']:.1f} cm over {r['err_frames']} frames")
        out.append(f"| {r['seq']} {r['sensor']} | {r['frames']} | {first} | {acq} | "
                   f"{r['tracked_in_field']} of {r['in_field_after']} (from acquisition on; {r['drone_frames']} "
                   f"with drone returns in all; {r['tracked_outside_field']} tracked in frames with an estimate but no drone return) | {med} | "
                   f"{r['sky_points']} in {r['sky_frames']} frames | {r['sky_tracks']} | {r['confirmed']} |")
    return "\n".join(out)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", type=Path)
    ap.add_argument("--sensor", action="append", help="sensor folder(s) in val/seqN (default: livox_avia and lidar_360)")
    ap.add_argument("--docs", type=Path, help="also write the docs page here, its plots in docs/img/real-recordings/")
    a = ap.parse_args()
    try:
        root = find_root(a.folder)
        sensors = a.sensor or ["livox_avia", "lidar_360"]
        runs = [(p.name, s) for p in sorted((root / "val").iterdir()) for s in sensors if (p / s).is_dir()]
        if not runs:
            raise UserError(f"{root / 'val'}: no seqN/{' or '.join(sensors)} folders")
        plot_dir = a.docs.parent / "img" / "real-recordings" if a.docs else None
        rows = [run_sequence(root, seq, s, plot_dir) for seq, s in runs]
    except UserError as exc:
        print(f"mmaud_table: error: {exc}", file=sys.stderr)
        return 2
    env = describe()
    print(env)
    print(table(rows))
    for r in rows:
        print(f"{r['seq']} {r['sensor']}: tracking took {r['wall_s']:.2f} s wall, {r['cpu_s']:.2f} s CPU for {r['frames']} frames "
              f"(load average {r['load']:.2f} on {os.cpu_count()} cores)")
    if a.docs:
        a.docs.write_text(docs_page(rows, env, a.docs.parent))
        print(f"-> {a.docs}")
    return 0


def docs_page(rows: list[dict], env: str, docs_dir: Path) -> str:
    load = "; ".join(f"{r['seq']} {r['sensor']}: {r['wall_s']:.2f} s wall, {r['cpu_s']:.2f} s CPU, load average {r['load']:.2f} "
                     f"on {os.cpu_count()} cores" for r in rows)
    return f"""# Real recordings: tracking a drone in recordings people already have

Generated by `python scripts/mmaud_table.py MMAUD_DIR --docs docs/real-recordings.md`, where `MMAUD_DIR`
is a copy of the repository `dtc111111/Multi-Modal-UAV` (MIT licence; the script fetches nothing).
Timing of the tracking runs: {load}.

## What was run

`foveatrack track` reads recordings made by someone else's fixed lidar: ROS 1 bags and ROS 2 bags
(MCAP or sqlite3; `sensor_msgs/msg/PointCloud2` with any field layout holding x, y, z, or the Livox
`CustomMsg` of `livox_ros_driver2` / `livox_ros_driver`), folders of PCD files, and folders of numpy
frames named by time (`foveatrack/sources/`).  With no hand-made space of interest D, the drone is
found as a moving object against the static scene and the sky (`foveatrack/openloop/`): the static
scene is learned from the scans over time and taken out, what is left is clustered into objects,
a drone-sized object with at least 5 returns in 3 of its first 5 frames is confirmed, and from
then on the paper's Algorithm 1 (the per-axis median, App. D.2) runs in a 2 m box D around it.
The run writes the track as CSV, PNG plots, the distance to a reference if one is given, and with
`--record` a Foxglove recording (MCAP) with the cloud, the track and each frame's D.

```
foveatrack track MMAUD_DIR/point_cloud_processing/val/seq1/livox_avia \\
    --reference MMAUD_DIR/point_cloud_processing/result/seq1 --csv track.csv --plot plots/ --record track.mcap
```

## MMAUD validation sequences

The MMAUD anti-UAV dataset (CVPR 2024 UG2+ challenge) publishes validation sequence 1 with a Livox
Avia (`livox_avia`: the sky around the drone, the scene already taken out) and a Livox Mid-360
(`lidar_360`: the whole scene, ground and trees, ~4000 returns a frame) looking up at a flying drone,
and one estimate per frame by a challenge team (theirs, not the ground truth: the distances below
are agreement with them, not an error against truth; the Mid-360 sees the drone for the whole
sequence, the Avia for its first 2.9 s).  "Drone
returns" are points within {DRONE_RADIUS_M} m of the team's estimate (the table's yardstick; the
tracker does not see the estimates); "stray sky returns" are points beyond {SKY_RANGE_M:.0f} m, and confirmed tracks beyond {SKY_RANGE_M:.0f} m are on
them (Avia) or on the scene's objects (Mid-360: posts, foliage in the wind; confirmed, never followed).

{table(rows)}

{figures(rows, docs_dir)}

## Limits seen

- Nothing tells a static drone-sized object from a hovering drone in the first 0.3 s: such an
  object is confirmed (the Mid-360 row: dozens of posts and trees at 12-40 m).  Of the objects
  confirmed together, the one highest above the sensor's XY plane is followed (the drone is the
  object against the sky; without that rule the Mid-360 run followed a post at 19 m); a confirmed
  object that stays within 0.5 m for 3 s is dropped as scenery and its D made background.  A drone
  that hovers that still for 3 s is lost the same way, and a drone below the scenery's elevation
  loses the choice: there, give D (`--box`).
- A fixed sensor's scenery is learned per direction as well as per cube of space (0.3 deg cells:
  a Livox Mid-40's rosette returns about once a frame from each, where a 0.3 m cube of ground 25 m
  out at grazing incidence is hit once in four frames and took ~4 s to learn).  In the first
  second, before that, patches of ground and wall make drone-sized objects that are confirmed, and
  while nothing above the sensor's XY plane is confirmed one of them may be followed; it gives way
  to a confirmed object above it.  Simulated fixed Mid-40, ground 1.5 m below, drones 12-18 m out:
  ground patches followed from 0.2 to 0.8 s and the drone from 0.9 s on, 19 confirmed tracks (per
  cube alone: ground patches to 2.8 s, the drone from 3.9 s, 27 tracks; with a wall at 40 m, wall
  patches at the field's rim all along and never the drone).  The same rule makes a drone flying
  below the sensor's plane give way to a confirmed object above it.  The table above was made
  before this; on the 18 frames of `tests/openloop/mmaud_seq1` the run is unchanged (the full
  sequences were not at hand to run again).
- The Mid-360's distance to the team's estimates is larger in its first 1.5 s (20-30 cm) than
  later; why is not known here (the sensors' extrinsics, the side of the drone each sees: the
  estimate is the team's, not truth).  Frames without an estimate (12 of 88) are not counted.
- The tests run on 18 frames cut from sequence 1 (`tests/openloop/mmaud_seq1/`, source and licence in
  its README), so the suite needs no network.

## How a recording's times are read

- A folder's file names are times since 1970: `<seconds>.<fraction>` (`1706255621.614239.npy`), or
  digits only, in the unit their number of digits gives (a time since 1970 has 10 digits in
  seconds, 13 in ms, 16 in µs, 19 in ns: up to 10 digits are seconds, 11-13 ms, 14-16 µs,
  17-19 ns; `1717243800005000.npy` is µs).  A folder whose names are in two units is refused,
  naming a file of each.
- A PointCloud2's per-point time (the first of the fields `timestamp`, `time`, `t`, `offset_time`) is
  read in the unit its datatype and name give, as the drivers publish them: an integer field is ns
  after `header.stamp` (Livox `offset_time`, Ouster `t`), a float64 `timestamp` an absolute time in
  ns (livox_ros_driver2) or seconds (Hesai; told apart by whether its values reach 1e15), any other
  float field seconds after `header.stamp` (Velodyne `time`).  A scan whose times spread over more
  than a second (or a frame period) is put at its stamp; one whose times lie further than that
  from its stamp (points on another clock: GPS time is 18 s ahead of UTC) keeps its points' times
  after its first point, put at the stamp.  Either is said once, naming the topic and message.
- A bag's frames are at their `header.stamp`s, read in the bag's order: stamps that go back or
  repeat are counted and said once at the end (with the first such message); a topic whose first
  10 messages (or all, if fewer) share one stamp, as when a publisher never sets it (0), is refused.
"""


def figures(rows: list[dict], docs_dir: Path) -> str:
    out = []
    for r in rows:
        for p in r["plots"]:
            rel = Path(os.path.relpath(p, docs_dir)).as_posix()
            out.append(f"![{r['seq']} {r['sensor']}: {p.stem}]({rel})")
    return "\n\n".join(out)


if __name__ == "__main__":
    sys.exit(main())
