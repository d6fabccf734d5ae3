"""Run scenes with the multi-object tracker ([tracker.sky], added here if the scene lacks it) over
seeds and print the issue-28 figures: per drone the time to a confirmed track after entering the
lidar's field, id switches, continuity, share of time in the fovea and the longest revisit gap; false
confirmed drone tracks per hour; GOSPA; and the drone/bird/clutter confusion matrix of the confirmed
tracks.  ``--markdown PATH`` also writes them as a docs page.

    .venv/bin/python scripts/sky_tracks_report.py scenes/two-drones-crossing.toml --seeds 8

Truth: the scene's ``ClosedLoop.objects_log`` (every object with id and class) where the simulator
keeps it, else the scene's ``[[target]]`` tables (all drones).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from collections import Counter, defaultdict

import numpy as np

from foveatrack.reconstruction import rotation_matrix
from foveatrack.sky.attention import bearing_off_axis_deg
from foveatrack.sky.metrics import drone_metrics, gospa
from sim.loop import ClosedLoop
from sim.scene import load_scene

TRUTH_CLASSES = ("drone", "bird", "clutter")
LABELS = ("drone", "bird", "clutter", "unknown")


def _truth_frames(loop, log):
    """Per frame: {id: (class, xyz (3,), visible)} of every object."""
    T = len(log["t_end_s"])
    objs = getattr(loop, "objects_log", None)
    out = []
    if objs:
        for k in range(T):
            out.append({o.id: ("drone" if o.cls == "drone" else "bird" if o.cls == "bird" else "clutter",
                               np.array(o.xyz_m, float), o.rays_hit > 0)
                        for o in objs[k] if not o.id.startswith("stray-")})
        return out
    for k in range(T):
        t_mid = log["t_end_s"][k] - 0.05
        out.append({f"target-{i}": ("drone", s.trajectory.position(np.array([t_mid]))[0], True)
                    for i, s in enumerate(loop.scene.targets)})
    return out


def run_one(scene, fovea_half_deg: float):
    loop = ClosedLoop(scene)
    t0 = time.perf_counter()
    log = loop.run()
    wall = time.perf_counter() - t0
    truth = _truth_frames(loop, log)
    T = len(truth)
    times = np.asarray(log["t_end_s"])
    drone_ids = sorted({i for fr in truth for i, (c, _, _) in fr.items() if c == "drone"})
    drones = {}
    for d in drone_ids:
        xyz = np.full((T, 3), np.nan)
        vis = np.zeros(T, bool)
        fov = np.zeros(T, bool)
        for k, fr in enumerate(truth):
            if d in fr:
                xyz[k] = fr[d][1]
                vis[k] = fr[d][2]
                rows = rotation_matrix(log["head_pan_deg"][k], log["head_tilt_deg"][k]).tolist()
                fov[k] = bearing_off_axis_deg(xyz[k], rows, np.zeros(3)) <= fovea_half_deg
        drones[d] = {"xyz_m": xyz, "visible": vis, "in_fovea": fov}
    tracks = [[(v.track_id, v.label, v.xyz_m) for v in o.sky.tracks if v.confirmed] for o in loop.sky_log]
    m = drone_metrics(times, drones, tracks)
    g = [gospa([x for _, _, x in tr], [drones[d]["xyz_m"][k] for d in drone_ids
                                       if np.all(np.isfinite(drones[d]["xyz_m"][k]))], 5.0)["distance"]
         for k, tr in enumerate(tracks)]
    # confusion: each confirmed track's majority truth class (matched within 2 m) vs its last label
    votes: dict[int, Counter] = defaultdict(Counter)
    last_label: dict[int, str] = {}
    for k, tr in enumerate(tracks):
        ids = list(truth[k])
        a = gospa([x for _, _, x in tr], [truth[k][i][1] for i in ids], 2.0)["assignment"] if tr and ids else []
        for i, j in a:
            votes[tr[i][0]][truth[k][ids[j]][0]] += 1
        for tid, label, _ in tr:
            last_label[tid] = label
    confusion = Counter()
    for tid, label in last_label.items():
        cls = votes[tid].most_common(1)[0][0] if votes[tid] else "clutter"
        confusion[(cls, label)] += 1
    m["false_causes"] = false_track_causes(m["false_drone_tracks"], tracks, truth)
    m["hours"] = T * float(np.median(np.diff(times))) / 3600.0 if T > 1 else 0.0
    return m, float(np.mean(g)), confusion, wall, T


def false_track_causes(false_ids, tracks, truth) -> Counter:
    """What each false drone track was: the class of the truth object nearest to it over the frames
    it was labelled drone (majority; "drone": a second or displaced track on a drone, which is not a
    bird or a tree)."""
    near: dict[int, Counter] = defaultdict(Counter)
    wanted = set(false_ids)
    for k, tr in enumerate(tracks):
        objs = [(c, x) for c, x, _ in truth[k].values() if np.all(np.isfinite(x))]
        for tid, label, x in tr:
            if tid in wanted and label == "drone" and objs:
                near[tid][min(objs, key=lambda o: float(np.sum((o[1] - x) ** 2)))[0]] += 1
    return Counter(near[t].most_common(1)[0][0] if near[t] else "clutter" for t in false_ids)


def summary_row(name, rows) -> str:
    """One scene over all its runs: the issue-28 figures that decide, with false drone tracks per hour
    of run by what they were near."""
    hours = sum(m["hours"] for _, m, *_ in rows)
    drones = [r for _, m, *_ in rows for r in m["drones"].values()]
    ttc = [r["time_to_confirm_s"] for r in drones]
    within = sum(1 for x in ttc if x is not None and x <= 2.0)
    gaps = [r.get("longest_revisit_gap_s", math.nan) for r in drones]
    causes = Counter()
    for _, m, *_ in rows:
        causes.update(m["false_causes"])
    per_h = " / ".join(f"{causes[c]} ({causes[c] / hours:.0f})" for c in ("bird", "clutter", "drone"))
    return (f"| {name} | {len(rows)} | {hours:.2f} | {len(drones)} | {within} | "
            f"{sum(r['id_switches'] for r in drones)} | {np.nanmedian(gaps):.1f} / {np.nanmax(gaps):.1f} | {per_h} |")


SUMMARY_HEAD = ("| scene | runs | scene-hours | drones | confirmed within 2 s | id switches | longest revisit gap, "
                "median / max [s] | false drone tracks (per hour) near a bird / a tree or clutter / a drone |\n"
                "|---|---|---|---|---|---|---|---|")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--first-seed", type=int, default=0,
                    help="seeds from the scene's own plus this (default 0): tune on others than you report")
    ap.add_argument("--duration", type=float, default=None, help="override the scenes' duration [s]")
    ap.add_argument("--markdown", default=None)
    ap.add_argument("--summary-only", action="store_true",
                    help="only the one-line summary per scene (for long runs: --seeds 180 is a scene-hour "
                         "of a 20 s scene)")
    ap.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE",
                    help="[tracker.sky] keys to set for the run (numbers), e.g. warmup_s=0.8 or "
                         "classifier.drone_after_frames=10")
    a = ap.parse_args(argv)
    lines = []
    summary = []
    total_conf = Counter()
    for path in a.scenes:
        base = load_scene(path)
        sky = dict(base.tracker_table.get("sky", {}))
        for kv in a.set:
            k, _, v = kv.partition("=")
            *tables, k = k.split(".")          # classifier.min_hits=6: a key of a sub-table
            t = sky
            for name in tables:
                t[name] = t = dict(t.get(name, {}))
            t[k] = int(v) if v.lstrip("-").isdigit() else float(v)
        table = {**base.tracker_table, "sky": sky}
        fovea = float(sky.get("attention", {}).get("fovea_half_angle_deg", 3.0))
        rows = []
        for s in range(a.first_seed, a.first_seed + a.seeds):
            scene = dataclasses.replace(base, seed=base.seed + s, tracker_table=table,
                                        **({"duration_s": a.duration} if a.duration else {}))
            m, g, conf, wall, T = run_one(scene, fovea)
            total_conf.update(conf)
            rows.append((scene.seed, m, g, wall, T))
            print(f"{base.name} seed {scene.seed}: {T} frames in {wall:.1f} s; GOSPA mean {g:.2f} m; "
                  f"false drone tracks {len(m['false_drone_tracks'])}", file=sys.stderr)
        summary.append(summary_row(base.name, rows))
        if a.summary_only:
            continue
        lines.append(f"## {base.name} ({a.seeds} seeds)\n")
        lines.append("| seed | drone | time to confirm [s] | time to the drone label [s] | id switches | continuity | "
                     "fovea share | longest revisit gap [s] |")
        lines.append("|---|---|---|---|---|---|---|---|")
        for seed, m, g, wall, T in rows:
            for d, r in m["drones"].items():
                ttc, ttl = ("never" if r[k] is None else f"{r[k]:.1f}" for k in ("time_to_confirm_s",
                                                                                 "time_to_drone_label_s"))
                lines.append(f"| {seed} | {d} | {ttc} | {ttl} | {r['id_switches']} | {r['continuity']:.2f} | "
                             f"{r.get('fovea_share', math.nan):.2f} | {r.get('longest_revisit_gap_s', math.nan):.1f} |")
        lines.append("")
        lines.append("| seed | false confirmed drone tracks | per hour | mean GOSPA (c = 5 m, p = 2) [m] | wall [s] |")
        lines.append("|---|---|---|---|---|")
        for seed, m, g, wall, T in rows:
            lines.append(f"| {seed} | {len(m['false_drone_tracks'])} | {m['false_drone_tracks_per_hour']:.0f} | "
                         f"{g:.2f} | {wall:.1f} |")
        lines.append("")
    lines[:0] = ["## Summary\n", SUMMARY_HEAD, *summary, ""]
    lines.append("## Confusion matrix of the confirmed tracks (rows: truth, columns: the track's last label)\n")
    lines.append("| truth \\ label | " + " | ".join(LABELS) + " |")
    lines.append("|---|" + "---|" * len(LABELS))
    for c in TRUTH_CLASSES:
        lines.append(f"| {c} | " + " | ".join(str(total_conf[(c, l)]) for l in LABELS) + " |")
    text = "\n".join(lines) + "\n"
    print(text)
    if a.markdown:
        with open(a.markdown, "w") as f:
            f.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
