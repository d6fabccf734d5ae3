"""The issue-28 figures of one closed-loop run of the multi-object tracker (``[tracker.sky]``), from
the run's log and the simulator's truth of every object: what ``foveatrack simulate`` prints for such
a run and what ``scripts/sky_tracks_report.py`` sums over seeds.

Per drone (:func:`foveatrack.sky.metrics.drone_metrics`): time from entering the lidar's field to a
confirmed track and to the drone label, continuity, id switches, share of time in the fovea, longest
revisit gap; the false confirmed drone tracks (and what each was near: a bird, a tree or clutter, a
drone); the mean GOSPA over the frames; and the confusion of each confirmed track's truth class
(majority of the frames it was matched within 2 m) against its last label.  Beside them, what the
scan's rays and the head's speeds allowed (:mod:`sim.sky_bounds`), and what the fovea did in each
drone's longest revisit gap (:func:`gap_reasons`).

Truth: the run's ``ClosedLoop.objects_log`` (every object with id and class) where the simulator
keeps it, else the scene's ``[[target]]`` tables (all drones).
"""

from __future__ import annotations

from collections import Counter, defaultdict

import numpy as np

from foveatrack.fixed_order import norm3
from foveatrack.sky.attention import true_off_axis_deg
from foveatrack.sky.track_paths import confirmed_paths
from foveatrack.sky.metrics import drone_metrics, gospa
from sim.sky_bounds import head_allows_revisit_s, head_limits, scan_allows_confirm_s

TRUTH_CLASSES = ("drone", "bird", "clutter")
LABELS = ("drone", "bird", "clutter", "unknown")
GOSPA_CUTOFF_M = 5.0


def truth_frames(loop, log) -> list[dict]:
    """Per frame: {id: (class, xyz (3,), visible)} of every object (stray near returns left out);
    ``visible``: the rays of the frame that hit it (0: none; 1 where the simulator kept no count)."""
    T = len(log["t_end_s"])
    objs = getattr(loop, "objects_log", None)
    out = []
    if objs:
        for k in range(T):
            out.append({o.id: ("drone" if o.cls == "drone" else "bird" if o.cls == "bird" else "clutter",
                               np.array(o.xyz_m, float), int(o.rays_hit))
                        for o in objs[k] if not o.id.startswith("stray-")})
        return out
    half = 0.5 * loop.tracker.config.period_s      # frame mid, as the truth is taken (not 10 Hz only)
    for k in range(T):
        t_mid = log["t_end_s"][k] - half
        out.append({f"target-{i}": ("drone", s.trajectory.position(np.array([t_mid]))[0], 1)
                    for i, s in enumerate(loop.scene.targets)})
    return out


def drone_truth(loop, log, truth) -> dict:
    """Per drone of ``truth`` (:func:`truth_frames`), by frame: ``xyz_m`` (T, 3) (NaN where absent),
    ``visible`` (hit by a ray), ``rays`` (how many), ``in_fovea`` (within the fovea's half-angle of the lidar's true axis)
    and ``in_field`` (in the scene's D and within the lidar's field at some pose the head can take:
    its elevation within the tilt limits widened by the field's half-angle; pan turns all round):
    what :func:`~foveatrack.sky.metrics.drone_metrics` takes.

    The field is the head's reach, not the lidar's field at the head's present pose: a drone the
    head has turned away from still waits for its revisit.  Counted at the present pose (before),
    a drone the schedule left outside the lidar's field stopped counting: the crossing's second drone,
    35 deg from the first at the end, had its last gap cut short where the head turned away for good,
    and the head's bound on the pair saw only the frames both drones were in one field."""
    fovea_half_deg = loop.sky.attention.cfg.fovea_half_angle_deg
    field_half_deg = loop.sky.sky.cfg.field_half_angle_deg
    tilt_lo, tilt_hi = loop.tracker.config.tilt_limits_deg
    region = loop.sky.sky.region
    T = len(truth)
    drone_ids = sorted({i for fr in truth for i, (c, _, _) in fr.items() if c == "drone"})
    drones = {}
    for d in drone_ids:
        xyz = np.full((T, 3), np.nan)
        rays = np.zeros(T, np.int64)
        for k, fr in enumerate(truth):
            if d in fr:
                xyz[k] = fr[d][1]
                rays[k] = fr[d][2]
        present = np.all(np.isfinite(xyz), axis=1)
        fov = present & (true_off_axis_deg(xyz, log["head_pan_deg"], log["head_tilt_deg"]) <= fovea_half_deg)
        # within the head's reach and inside the scene's space of interest (a drone that has flown out
        # of D is no longer the tracker's to revisit)
        el = np.degrees(np.arctan2(xyz[:, 2], np.hypot(xyz[:, 0], xyz[:, 1])))
        half = 90.0 if field_half_deg is None else field_half_deg
        field = present & (el >= tilt_lo - half) & (el <= tilt_hi + half)
        if region is not None and present.any():
            field[present] &= np.asarray(region.contains(xyz[present]), bool)
        drones[d] = {"xyz_m": xyz, "visible": rays > 0, "rays": rays, "in_fovea": fov, "in_field": field}
    return drones


def _scan_bounds(loop, log, drones: dict, m: dict) -> None:
    """Each drone's :func:`scan_allows_confirm_s`, with the tracker's warm-up (``scan_allows_confirm_s``;
    with ``warmup_replay`` the warm-up's hits count, reported at its end) and without it
    (``..._no_warmup_s``), into ``m["drones"]``."""
    cfg = loop.sky.sky.cfg
    t = np.asarray(log["t_end_s"], np.float64)
    if t.size == 0:
        return
    start = t[0] - loop.tracker.config.period_s     # the first frame's start, as the tracker counts
    after_warmup = t - start > cfg.warmup_s
    # with warmup_replay the warm-up's frames are tracked at its end: their hits count, reported then
    tracked = np.ones(t.size, bool) if cfg.warmup_replay else after_warmup
    reported_from = int(np.argmax(after_warmup)) if cfg.warmup_replay and after_warmup.any() else 0
    for d, a in drones.items():
        r = m["drones"][d]
        r["scan_allows_confirm_s"] = scan_allows_confirm_s(t, tracked, a["rays"], cfg.min_points,
                                                           cfg.confirm_hits, cfg.confirm_window, reported_from,
                                                           cfg.lone_returns)
        r["scan_allows_confirm_no_warmup_s"] = scan_allows_confirm_s(t, np.ones(t.size, bool), a["rays"],
                                                                     cfg.min_points, cfg.confirm_hits,
                                                                     cfg.confirm_window, lone_returns=cfg.lone_returns)


def _head_bounds(loop, log, drones: dict, m: dict) -> None:
    """:func:`head_allows_revisit_s` of the run: each drone's ``head_allows_acquire_s`` into
    ``m["drones"]``, the run's bound into ``m["head_allows_revisit_s"]``."""
    given = {d: {**a, "first_s": m["drones"][d]["first_matched_s"]} for d, a in drones.items()}
    b = head_allows_revisit_s(log["t_end_s"], log["head_pan_deg"], log["head_tilt_deg"], given,
                              head_limits(loop), loop.sky.attention.cfg.fovea_half_angle_deg)
    for d, r in m["drones"].items():
        r["head_allows_acquire_s"] = b["acquire_s"].get(d)
    m["head_allows_revisit_s"] = b["bound_s"]


GAP_REASONS = ("turning to it", "serving another drone", "serving a track not on a drone",
               "its track looks no drone", "no confirmed track on it")     # the report's columns


def gap_reasons(loop, log, drones: dict, m: dict) -> dict:
    """Per drone, what the fovea did in the frames of its longest revisit gap (the frames
    :func:`~foveatrack.sky.metrics.drone_metrics` counts), each frame one of :data:`GAP_REASONS`, by
    the confirmed track nearest the drone within 2 m (its track) and the track the fovea served:
    its track (the head is turning to it); a track within 2 m of another drone; another track, or
    none; before those two, its track looks like no drone (the schedule revisits only what looks
    like one); or it had no confirmed track.  What a long gap is made of: the head's
    turn, the other drones, the classifier or the tracker."""
    out = {}
    t = np.asarray(log["t_end_s"], np.float64)
    dt = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    for d, a in drones.items():
        r = m["drones"][d]
        if r.get("first_matched_s") is None or r.get("longest_revisit_gap_s") is None:
            continue
        since = r.get("longest_revisit_gap_from_s")
        start = 0 if since is None else int(np.searchsorted(t, since - 1e-9))
        n = int(round(r["longest_revisit_gap_s"] / dt)) if dt > 0 else 0
        reasons = Counter()
        for k in range(start, start + n):
            o = loop.sky_log[k]
            x = a["xyz_m"][k]
            views = {v.track_id: v for v in o.sky.tracks if v.confirmed}
            near = min(((norm3(v.xyz_m - x), tid) for tid, v in views.items()), default=(np.inf, None))
            own = near[1] if near[0] < 2.0 else None
            fix = views.get(o.fixated)
            others = [e for e in drones if e != d and np.all(np.isfinite(drones[e]["xyz_m"][k]))]
            if own is None:
                reasons["no confirmed track on it"] += 1
            elif o.fixated == own:
                reasons["turning to it"] += 1
            elif views[own].looks_like != "drone":
                reasons["its track looks no drone"] += 1
            elif fix is not None and any(norm3(fix.xyz_m - drones[e]["xyz_m"][k]) < 2.0 for e in others):
                reasons["serving another drone"] += 1
            else:
                reasons["serving a track not on a drone"] += 1
        out[d] = reasons
    return out


def sky_run_figures(loop, log) -> tuple[dict, float, Counter]:
    """``(metrics, mean GOSPA [m], confusion)`` of a finished run of the multi-object tracker
    (module docstring); ``metrics`` is :func:`~foveatrack.sky.metrics.drone_metrics`' with
    ``false_causes`` (a Counter by what each false drone track was near) and ``hours`` of run."""
    truth = truth_frames(loop, log)
    T = len(truth)
    times = np.asarray(log["t_end_s"])
    drones = drone_truth(loop, log, truth)
    drone_ids = sorted(drones)
    tracks = [[(v.track_id, v.label, v.xyz_m) for v in o.sky.tracks if v.confirmed] for o in loop.sky_log]
    m = drone_metrics(times, drones, tracks)
    _scan_bounds(loop, log, drones, m)
    _head_bounds(loop, log, drones, m)
    g = [gospa([x for _, _, x in tr], [drones[d]["xyz_m"][k] for d in drone_ids
                                       if np.all(np.isfinite(drones[d]["xyz_m"][k]))], GOSPA_CUTOFF_M)["distance"]
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
    m["confirmed_tracks"] = len(last_label)
    m["gap_reasons"] = gap_reasons(loop, log, drones, m)
    return m, float(np.mean(g)) if g else float("nan"), confusion


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


CONFIRM_BOUND_S = 2.0      # issue 28: every drone confirmed within 2 s of entering the field
REVISIT_S = 3.0            # issue 28: each drone in the fovea at least once per revisit time


def within_bound(drones, key: str = "time_to_confirm_s") -> int:
    """How many of the drones' figure rows have ``key`` (a time after entering the field) within
    :data:`CONFIRM_BOUND_S`."""
    return sum(1 for r in drones if r.get(key) is not None and r[key] <= CONFIRM_BOUND_S)


def sky_totals(drones: dict, false_drone_tracks, gospa_mean_m: float, head_allows_revisit_s: float | None = None) -> dict:
    """One run's figures over all its drones, as plain numbers (the Monte Carlo regression's,
    ``tests/regression/test_sky_monte_carlo.py``): drones; confirmed within 2 s; the same the scan's
    rays allowed; never confirmed; the median time to confirm of those confirmed; id switches; false
    drone tracks; mean continuity and fovea share; the longest revisit gap and the shortest the head's
    speed allowed (:func:`head_allows_revisit_s`); mean GOSPA."""
    rs = list(drones.values())
    ttc = [r["time_to_confirm_s"] for r in rs if r["time_to_confirm_s"] is not None]
    gaps = [r["longest_revisit_gap_s"] for r in rs if r.get("longest_revisit_gap_s") is not None]
    return {"drones": len(rs), "confirmed_within_2s": within_bound(rs),
            "scan_allows_within_2s": within_bound(rs, "scan_allows_confirm_s"),
            "never_confirmed": sum(1 for r in rs if r["time_to_confirm_s"] is None),
            "time_to_confirm_s": float(np.median(ttc)) if ttc else None,
            "id_switches": sum(r["id_switches"] for r in rs), "false_drone_tracks": len(false_drone_tracks),
            "continuity": float(np.mean([r["continuity"] for r in rs])) if rs else None,
            "fovea_share": float(np.mean([r.get("fovea_share", 0.0) for r in rs])) if rs else None,
            "longest_revisit_gap_s": max(gaps) if gaps else None, "head_allows_revisit_s": head_allows_revisit_s,
            "gospa_mean_m": gospa_mean_m}


def sky_summary(loop, log) -> dict:
    """The figures of :func:`sky_run_figures` as JSON-plain values (``foveatrack simulate --json``),
    with their :func:`sky_totals`."""
    m, g, confusion = sky_run_figures(loop, log)
    return {"drones": m["drones"], "totals": sky_totals(m["drones"], m["false_drone_tracks"], g,
                                                        m["head_allows_revisit_s"]),
            "false_drone_tracks": list(m["false_drone_tracks"]),
            "false_drone_tracks_near": dict(m["false_causes"]), "confirmed_tracks": m["confirmed_tracks"],
            "gospa_mean_m": g, "gospa_cutoff_m": GOSPA_CUTOFF_M,
            "confusion": [{"truth": c, "label": lab, "tracks": n} for (c, lab), n in sorted(confusion.items())]}


def _sooner(r: dict) -> bool:
    """Whether a drone's track was confirmed before the scan's rays on the drone itself allowed (a
    neighbour's returns in its objects: sim.sky_bounds.scan_allows_confirm_s bounds its own rays)."""
    ttc, allowed = r.get("time_to_confirm_s"), r.get("scan_allows_confirm_s")
    return ttc is not None and allowed is not None and ttc < allowed - 1e-9


def _count(n: int, one: str, many: str | None = None) -> str:
    """``1 drone``, ``2 drones``."""
    return f"{n} {one if n == 1 else (many or one + 's')}"


def sky_lines(s: dict) -> list[str]:
    """The printed lines of :func:`sky_summary`."""
    fmt = lambda v: "never" if v is None else f"{v:.1f} s"      # noqa: E731
    out = [f"  multi-object tracker: {_count(len(s['drones']), 'drone')}, "
           f"{_count(s['confirmed_tracks'], 'confirmed track')}, {_count(len(s['false_drone_tracks']), 'false drone track')}"
           + (" (near " + ", ".join(f"{k} {v}" for k, v in sorted(s["false_drone_tracks_near"].items())) + ")"
              if s["false_drone_tracks"] else "")
           + f"; mean GOSPA {s['gospa_mean_m']:.2f} m (c = {s['gospa_cutoff_m']:g} m)"]
    for d, r in s["drones"].items():
        bound = ""
        if "scan_allows_confirm_s" in r:
            bound = (f" (the scan's rays on it allowed {fmt(r['scan_allows_confirm_s'])}, "
                     f"{fmt(r['scan_allows_confirm_no_warmup_s'])} without the warm-up"
                     + ("; sooner than its own rays allowed: the objects its track was confirmed on held "
                        "other returns too" if _sooner(r) else "") + ")")
        out.append(f"  {d}: confirmed {fmt(r['time_to_confirm_s'])} after entering the field{bound}, labelled drone "
                   f"{fmt(r['time_to_drone_label_s'])}; track ids {r['track_ids'] or '-'}, "
                   f"{_count(r['id_switches'], 'id switch', 'id switches')}, continuity {r['continuity']:.2f}; in the fovea {100 * r.get('fovea_share', 0):.0f} % "
                   f"of its time in the field, longest gap "
                   + ("never tracked" if r.get("longest_revisit_gap_s", 0.0) is None
                      else f"{r.get('longest_revisit_gap_s', float('nan')):.1f} s")
                   + (f" (the head's speed allowed its first {fmt(r['head_allows_acquire_s'])})"
                      if r.get("head_allows_acquire_s") is not None else ""))
    bound = s["totals"].get("head_allows_revisit_s")
    if bound is not None:
        gap = s["totals"]["longest_revisit_gap_s"]
        out.append(f"  revisits: longest gap {fmt(gap)}; the head's top speeds allowed no less than {fmt(bound)} "
                   f"(revisit time {REVISIT_S:g} s)")
    return out


def sky_plot_data(loop, log) -> dict:
    """What ``tracks.png`` draws (:func:`foveatrack.cli.sim_plots.plot_sky_tracks`): ``t_s`` (T,);
    ``truth``: id -> (class, (T, 3) positions, NaN where absent); ``tracks``: id -> ((T,) labels, "" where not confirmed,
    (T, 3) positions while confirmed, NaN elsewhere, (T,) measured that frame:
    :func:`foveatrack.sky.track_paths.confirmed_paths`); ``in_fovea``: drone id -> (T,) bool."""
    truth = truth_frames(loop, log)
    T = len(truth)
    objs: dict[str, tuple[str, np.ndarray]] = {}
    for k, fr in enumerate(truth):
        for i, (c, x, _) in fr.items():
            if i not in objs:
                objs[i] = (c, np.full((T, 3), np.nan))
            objs[i][1][k] = x
    tracks = confirmed_paths(([(v.track_id, v.confirmed, v.label, v.xyz_m, v.hit) for v in o.sky.tracks]
                              for o in loop.sky_log), T)
    fovea = {d: a["in_fovea"] for d, a in drone_truth(loop, log, truth).items()}
    return {"t_s": np.asarray(log["t_end_s"], float), "truth": objs, "tracks": tracks, "in_fovea": fovea}
