"""The study's markdown report, written from the results dict alone (every number in it is measured
by the run that produced the dict; the prose only names what the tables hold)."""

from __future__ import annotations

import math

from sim.study.calibration_time import PLANS
from sim.study.sensing import target_scene
from sim.study.runner import TARGETS
from sim.study.stats import LEVEL, excludes_zero, fmt as _ci, interval

COMMAND = "foveatrack study accuracy-vs-time --out docs --workers 2 --overwrite"


def _f(v, fmt="{:.3g}", none="-") -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return none
    return fmt.format(v + 0.0 if isinstance(v, float) else v)     # + 0.0: no "-0" for a zero bound


def _table(head: list[str], rows: list[list[str]]) -> list[str]:
    out = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return out + [""]


def _delta(iv) -> str:
    """A paired change with its interval; **bold** where the interval excludes zero (a measured effect)."""
    if iv is None:
        return "-"
    txt = _ci(iv)
    return f"**{txt}**" if excludes_zero(iv) else txt


def _ci_of(row: dict, key: str, scale: float = 1.0, digits: str = "{:.3g}") -> str:
    iv = (row.get("ci") or {}).get(key)
    if iv is None:
        return _f(row.get(key))
    if scale != 1.0:
        iv = dict(iv, mean=iv["mean"] * scale, half=None if iv["half"] is None else iv["half"] * scale)
    return _ci(iv, digits)


def seeds_vs_width(values: list[float], level: float = LEVEL) -> list[tuple[int, float | None]]:
    """Half-width of the interval of the mean from the first n per-seed values, n = 2..len: what
    more seeds buy."""
    return [(n, interval(values[:n], level)["half"]) for n in range(2, len(values) + 1)]


def _img(images: dict, key: str, alt: str) -> list[str]:
    return [f"![{alt}]({images[key]})", ""] if key in images else []


def headlines(res: dict) -> list[str]:
    ax = res["axes"]
    out = []
    for o in ax["scan"]["optics"]:
        ex = next(r for r in o["rows"] if r["model"] == "exact")
        pa = next(r for r in o["rows"] if r["model"] == "paraxial")
        out.append(f"- Scan model, {o['optics']}: paraxial costs {_f(pa['ns_per_ray'], '{:.0f}')} ns/ray against "
                   f"{_f(ex['ns_per_ray'], '{:.0f}')} ns/ray for exact refraction, with a p95 error of "
                   f"{_f(pa['p95_deg'])} deg (max {_f(pa['max_deg'])} deg).")
    for key, f in ax["fidelity"].items():
        rows = {r["setting"]: r for r in f["rows"]}
        ref, cheap = rows.get(f["reference"]), rows.get("all-cheap")
        if ref and cheap:
            d = cheap["delta"]["error_rms_all_deg"]
            moved = [r["setting"] for r in f["rows"] if excludes_zero(r["delta"]["error_rms_all_deg"])]
            out.append(f"- Simulation fidelity, {f['scene']}: all-cheap costs {_ci(cheap['cost_ratio'])} of all-exact's CPU "
                       f"and changes the tracking error rms by {_ci(d)} deg ({int(LEVEL * 100)} % interval over "
                       f"{cheap['seeds']} paired seeds); settings whose change is outside the noise: "
                       f"{', '.join(moved) if moved else 'none'}.")
    for target, t in ax["sensing"]["targets"].items():
        rows = t["rows"]
        if rows:
            a, b = rows[0], rows[-1]
            out.append(f"- Sensing, {target} ({t['scene']}): window {a['window_ms']:g} -> {b['window_ms']:g} ms takes "
                       f"detection probability {_ci_of(a, 'p_detect', digits='{:.2f}')} -> {_ci_of(b, 'p_detect', digits='{:.2f}')}, "
                       f"tracking error rms over all frames {_ci_of(a, 'error_rms_all_deg')} -> {_ci_of(b, 'error_rms_all_deg')} deg, latency "
                       f"{_f(None if a['latency_mean_s'] is None else 1000 * a['latency_mean_s'], '{:.0f}')} -> "
                       f"{_f(None if b['latency_mean_s'] is None else 1000 * b['latency_mean_s'], '{:.0f}')} ms.")
    for name, c in ax["sensing"]["coverage"].items():
        out.append(f"- Coverage, {name}: 50 % after {_f(c['t50_s'])} s, 90 % after {_f(c['t90_s'])} s "
                   f"with no speed noise (paper Fig. 6e, its prototype's prisms with their speed noise in a real "
                   f"scene: 0.3 s and 0.8 s; `foveatrack lidar coverage prototype --noise 0.01`: 0.28 s and 0.87 s).")
    cal = [r for r in ax["calibration"]["rows"] if r["plan"] not in ("nominal", "truth") and r["tilt_prior"]]
    nom = next((r for r in ax["calibration"]["rows"] if r["plan"] == "nominal"), None)
    if cal:
        best = min(cal, key=lambda r: r["table_err_all_pct"] if r["table_err_all_pct"] is not None else math.inf)
        out.append(f"- Calibration: the best table ({best['plan']} plan, dwell {best['dwell_s']:g} s, "
                   f"{_f(best['cal_virtual_s'], '{:.0f}')} s on the head) is {_f(best['table_err_all_pct'])} % rms off "
                   f"over the moving bytes; without calibration (nominal table) "
                   f"{_f(nom['table_err_all_pct'] if nom else None)} %, pointing reconstruction "
                   f"{_f(nom['pointing_rms_deg'] if nom else None)} deg rms vs {_f(best['pointing_rms_deg'])} deg.")
    for key, r in ax["rate"].items():
        rows = {x["preset"]: x for x in r["rows"]}
        if "mid40" in rows and "horizon" in rows:
            m, h = rows["mid40"], rows["horizon"]
            out.append(f"- Point rate, {r['scene']}: Horizon tracker {_ci_of(h, 'tracker_ms_per_frame')} ms/frame vs Mid-40 "
                       f"{_ci_of(m, 'tracker_ms_per_frame')}; tracking error rms {_ci_of(h, 'error_rms_all_deg')} vs "
                       f"{_ci_of(m, 'error_rms_all_deg')} deg; points on target {_f(h['points_on_target_per_frame'])} vs "
                       f"{_f(m['points_on_target_per_frame'])} per frame.")
    lv = ax.get("levers")
    if lv:
        for r in lv["rows"]:
            if r["lever"] == lv["reference"]:
                continue
            d, dm = r["delta"]["error_rms_acq_deg"], r["delta"]["recon_rms_m"]
            out.append(f"- Lever, {r['lever']} ({lv['scene']}): tracking error after acquisition {_delta(d)} deg, "
                       f"world position {_delta(dm)} m, CPU x{_ci(r['cost_ratio'])} of the paper's loop.")
    ob = {r["case"]: r for r in (ax.get("objects") or {}).get("rows", [])}
    lo, hi, sw = ob.get("drone-and-flock, 0 birds"), ob.get("drone-and-flock, 80 birds"), \
        ob.get("swarm-of-five + the 20-bird flock")
    if lo and hi and sw:
        out.append(f"- Sky (multi-object tracker): 0 -> 80 birds take a frame {_ci(lo['ci']['ms_per_frame'])} -> "
                   f"{_ci(hi['ci']['ms_per_frame'])} ms of CPU; the swarm with the 20-bird flock "
                   f"{_ci(sw['ci']['ms_per_frame'])} ms ({_f(sw.get('x_real_time'), '{:.0f}')}x real time), of it the "
                   f"tracker {_ci(sw['ci']['tracker_ms_per_frame'])} ms.")
    return out + [""]


def write_report(res: dict, images: dict[str, str], meta: dict) -> str:
    """The markdown text.  ``images``: {axis: path relative to the report}; ``meta``: how it ran
    (``command``, ``workers``, ``scheduler``, ``wall_s``, ``cpus``)."""
    ax = res["axes"]
    L: list[str] = ["# What accuracy costs in time", ""]
    L += [f"Generated by `{meta.get('command', COMMAND)}` ({res['size']} study: {res['tasks']} runs, "
          f"{_f(meta.get('wall_s'), '{:.0f}')} s wall on {meta.get('workers', '?')} workers"
          f"{' at ' + meta['scheduler'] if meta.get('scheduler') else ''}, {_f(res['task_cpu_s'], '{:.0f}')} s of "
          f"measured CPU; CPU: {meta.get('cpu', 'not recorded')}, load {_f(meta.get('load_1min_start'), '{:.1f}')} at the "
          f"start and {_f(meta.get('load_1min_end'), '{:.1f}')} at the end).  Regenerate with `{COMMAND}`; `--quick` runs "
          "a small version in about a minute (into another `--out`: a study's directory keeps its report unless "
          "`--overwrite`).", "",
          f"Every closed-loop figure is a mean over seeds with its {int(LEVEL * 100)} % Student-t interval (`mean ± "
          "half-width`); the per-seed values are in the JSON.  Changes against a reference are paired by seed, and "
          "**bold** marks a change whose interval excludes zero: only those are measured effects.  Costs are also "
          "given as ratios to a reference measured in the same run, which carry across machines better than "
          "seconds do.", "",
          "Every axis is a measured curve.  **Cost** of a simulation setting is the CPU time of the worker process "
          "(`time.process_time`) per virtual second or per frame: the study runs on shared machines, where wall "
          "time also measures the neighbours (wall time is in the JSON next to it).  Each worker loads numba's "
          "cached kernels before it measures anything.  Micro-benchmarks of the scan kernels use the minimum wall "
          "time of several repeats.  Raw numbers: `accuracy-vs-time.json` beside this file.", ""]
    L += ["## Headlines", ""] + headlines(res)

    # 1 ----------------------------------------------------------------------------------------
    L += ["## 1. Scan model fidelity: angular error per ray vs time per ray", "",
          "Exact vector refraction (the reference) and the paraxial vector sum, evaluated on the same "
          "consecutive rays of the real pattern; `exact/m` traces every m-th point of each channel exactly and "
          "interpolates between (a candidate the simulator does **not** offer; measured to see whether a "
          "cheaper exact-based model would pay).  **float32 is not offered**: every scan kernel is float64.", ""]
    for o in ax["scan"]["optics"]:
        L += [f"**{o['optics']}** ({o['valid_rays']} rays from point {o['k0']}):", ""]
        L += _table(["model", "ns / ray", "error rms [deg]", "p95 [deg]", "max [deg]", "in the simulator"],
                    [[r["model"], _f(r["ns_per_ray"], "{:.1f}"), _f(r["rms_deg"]), _f(r["p95_deg"]), _f(r["max_deg"]),
                      "yes" if r["offered"] else "no (study only)"] for r in o["rows"]])
    L += _img(images, "scan", "scan model error vs time per ray")

    # 2 ----------------------------------------------------------------------------------------
    L += ["## 2. Simulation fidelity: effect on the tracking metrics vs CPU time", "",
          "Each knob of the closed loop varied alone from the scene as shipped (`baseline`: footprint as the scene "
          "lists it, target moving per point, head pose on a 1 ms grid), plus `all-exact` (15 footprint sub-rays, "
          "per-point target, head pose exact at every point: the **reference**) and `all-cheap`.  Deviations are "
          "paired by seed (same seed, reference vs setting), averaged over seeds.  Any change of a knob changes "
          "how many random numbers the noise streams draw, so the *seed-to-seed spread* of the reference is the "
          "floor below which a deviation means nothing.  "
          "`head exact pieces` is the loop's default route: each point's pose exactly from the head's "
          "constant-acceleration pieces (`head exact` asks the head model about every point instead).", ""]
    for key, f in ax["fidelity"].items():
        fl = f["noise_floor"]
        L += [f"**{f['scene']}** (shortened to {f['duration_s']:g} s, seeds {', '.join(map(str, f['seeds']))}; "
              f"seed-to-seed spread: error rms {_f(fl['error_rms_all_deg'])} deg, points on target "
              f"{_f(fl['points_on_target_per_frame'])} per frame):", ""]
        L += _table(["setting", "footprint", "target", "head grid [ms]", "CPU vs reference", "error rms, all frames [deg]",
                     "Δ error rms, all [deg]", "Δ error rms after acq. [deg]", "Δ acquisition [s]",
                     "points on target / frame", "Δ points"],
                    [[r["setting"], r["footprint"], r["target_motion"].replace("_", "-"), _f(r["head_grid_ms"], "{:g}", none="exact (pieces)"),
                      _ci(r["cost_ratio"]), _ci_of(r, "error_rms_all_deg"), _delta(r["delta"]["error_rms_all_deg"]),
                      _delta(r["delta"]["error_rms_acq_deg"]), _delta(r["delta"]["acquisition_s"]),
                      _f(r["points_on_target_per_frame"]), _delta(r["delta"]["points_on_target_per_frame"])]
                     for r in f["rows"]])
    L += ["Error rms over all frames is the target's true off-axis angle at every frame; after acquisition, "
          "from the first of five frames in a row within the dead band + 1 deg.  `fast-crossing-close` is no longer "
          "used here: the tracker never acquires it, so its error measured the crossing, not the setting.", ""]
    L += _img(images, "fidelity", "simulation fidelity vs cost")

    # 3 ----------------------------------------------------------------------------------------
    L += ["## 3. Sensing time: accumulation window", "",
          "The tracker's frame is the accumulation window (`rate_hz = 1 / window`).  Detection probability: "
          "frames with a detection / frames with the target inside the FoV.  Bearing error: detection (median "
          "point) vs the true target centre in the lidar frame at the detection's timestamp with the head's "
          "true pose.  Control latency: when the command's last byte reaches the head minus the detection's "
          "timestamp (the head's 40 ms dead time comes on top).  `near` is fig12-tracking as shipped; `far` is "
          f"far-target-range-limit (a {_orbit_m('far'):g} m circle around the head) and `mid` the same geometry "
          f"scaled to {_orbit_m('mid'):g} m, both with the head pointed at the target's start so the window, not "
          "the acquisition, is measured.", ""]
    for target, t in ax["sensing"]["targets"].items():
        L += [f"**{target}** ({t['scene']}, {_f(t['duration_s'], '{:g}')} s per run):", ""]
        L += _table(["window [ms]", "seeds", "detections / frames in FoV", "P(detect)", "tracking error rms, all frames [deg]",
                     "tracking error after acq. [deg]", "latency mean [ms]", "bearing rms, detected frames only [deg]",
                     "points / detection"],
                    [[_f(r["window_ms"], "{:g}"), str(r["seeds"]), f"{r['detections']} / {r['frames_in_fov']}",
                      _ci_of(r, "p_detect"), _ci_of(r, "error_rms_all_deg"), _ci_of(r, "error_rms_acq_deg"),
                      _ci_of(r, "latency_mean_s", 1000.0, "{:.0f}"), _ci_of(r, "bearing_rms_deg"),
                      _f(r["points_per_detection"], "{:.1f}")] for r in t["rows"]])
    L += ["The bearing error is measured on detected frames only, so it favours windows that rarely detect "
          "(selection); the front below ranks windows by the tracking error over all frames instead.", ""]
    L += _img(images, "sensing", "sensing window")
    cov = ax["sensing"]["coverage"]
    if cov:
        windows = list(next(iter(cov.values()))["at_windows"])
        L += ["Coverage vs accumulation time (paper Fig. 6e; Appendix C voxel definition: 100 x 100 az/el grid, "
              "cells the scanner can reach; no speed noise):", ""]
        L += _table(["scanner", "cells"] + [f"{w} ms" for w in windows] + ["50 % at [s]", "90 % at [s]"],
                    [[n, str(c["cells"])] + [_f(100 * c["at_windows"][w], "{:.1f} %") for w in windows]
                     + [_f(c["t50_s"]), _f(c["t90_s"])] for n, c in cov.items()])
        L += _img(images, "coverage", "coverage vs accumulation time")

    # 4 ----------------------------------------------------------------------------------------
    cal = ax["calibration"]
    L += ["## 4. Calibration time: dwell per speed byte", "",
          f"The speed table calibrated by tracking a room corner (paper App. D.4) in a simulated "
          f"{' x '.join(f'{v:g}' for v in cal['room_m'])} m room, the head (unit {cal['unit_seed']}) driven by the "
          "calibrator through the virtual UART; then that table drives the dead reckoning of fig12-tracking on the "
          "same unit.  Calibration time is virtual time on the head.  Table error: rms relative error over the "
          "bytes moving at >= 10 % of the axis's top speed (the plan's bytes, and all bytes with the table's "
          "interpolation), rms absolute error over bytes 1-63.  Pointing error: reconstructed vs true optical "
          "axis at every frame end.  `nominal` = no calibration (linear nominal table); `truth` = the unit's own "
          "curve (an infinitely long calibration).  Byte plans: " +
          "; ".join(f"{name}: pan {', '.join(map(str, PLANS[name][0]))}, tilt {', '.join(map(str, PLANS[name][1]))}"
                    for name in dict.fromkeys(r["plan"] for r in cal["rows"]) if name in PLANS) + ".", ""]
    L += _table(["plan", "dwell [s]", "start-tilt prior", "runs", "calibration time [s]", "table err, measured bytes [%]",
                 "table err, all bytes [%]", "abs err pan / tilt [deg/s]", "dead time [ms]", "accel [deg/s²]",
                 "pointing rms [deg]", "pointing max [deg]", "pointing rms, true timing [deg]", "world position rms [m]"],
                [[r["plan"], _f(r["dwell_s"], "{:g}") if r["plan"] not in ("nominal", "truth") else "-",
                  "yes" if r["tilt_prior"] else "no", f"{r['runs'] - r['failed']}/{r['runs']}",
                  _f(r["cal_virtual_s"], "{:.0f}", none="inf" if r["plan"] == "truth" else "-"),
                  _ci_of(r, "table_err_measured_pct"), _ci_of(r, "table_err_all_pct"),
                  f"{_f(r['table_abs_pan_deg_s'])} / {_f(r['table_abs_tilt_deg_s'])}",
                  _f(None if r.get("table_dead_time_s") is None else 1000 * r["table_dead_time_s"], "{:.0f}"),
                  _f(r.get("table_accel_deg_s2")),
                  _ci_of(r, "pointing_rms_deg"), _f(r["pointing_max_deg"]), _f(r.get("pointing_rms_true_timing_deg")),
                  _ci_of(r, "recon_rms_m")] for r in cal["rows"]])
    tim = next((r for r in cal["rows"] if r.get("true_dead_time_s") is not None), None)
    if tim is not None:
        L += [f"The head's true timing: dead time {_f(1000 * tim['true_dead_time_s'], '{:.0f}')} ms, acceleration "
              f"pan {_f(tim['true_accel_pan_deg_s2'])} / tilt {_f(tim['true_accel_tilt_deg_s2'])} deg/s² (the "
              "calibrator, `PriorAxisCalibrator`, refits each leg's angle history with one dead time and one "
              "acceleration per axis; the `accel` column is the table-wide value).  "
              "`pointing rms, true timing` reruns the check with the measured speeds but the true timing: the "
              "difference to `pointing rms` is what the timing estimate costs, the rest is the speed entries.", ""]
    noprior = [r for r in cal["rows"] if not r["tilt_prior"]]
    if noprior:
        r = noprior[0]
        L += [f"Start-tilt prior: the calibrator finds the pan axis in the lidar frame from the corner's motion, "
              f"blended with the prior `CalibrationPlan.start_tilt_deg` by their uncertainties.  Without the prior "
              f"(implied start tilt {_f(r['implied_start_tilt_deg'], '{:.1f}')} deg, "
              f"true {_f(math.degrees(math.atan2(cal['corner_m'][2], math.hypot(*cal['corner_m'][:2]))), '{:.1f}')} "
              "deg) every pan speed is scaled by cos(tilt error); the row without the prior shows what that costs.", ""]
    L += _img(images, "calibration", "calibration time")

    # 5 ----------------------------------------------------------------------------------------
    L += ["## 5. Point rate / channels", "",
          "The same scenes with the lidar swapped: Mid-40 (100 k points/s, one channel, 38.4 deg circular) vs "
          "Horizon (240 k points/s, six channels, 81.7 x 25.1 deg).  Tracker CPU is `Tracker.process` alone (what "
          "runs on the real system); the simulated frame is everything.", ""]
    for key, r in ax["rate"].items():
        L += [f"**{r['scene']}** ({r['duration_s']:g} s):", ""]
        L += _table(["lidar", "seeds", "points / frame", "points on target / frame", "detections / frame",
                     "error rms all [deg]", "error rms after acquisition [deg]", "acquisition [s]",
                     "tracker CPU / frame [ms]", "simulated frame CPU [ms]"],
                    [[x["preset"], str(x["seeds"]), _f(x["points_per_frame"], "{:.0f}"), _f(x["points_on_target_per_frame"]),
                      _f(x["detect_frac"], "{:.2f}"), _ci_of(x, "error_rms_all_deg"), _ci_of(x, "error_rms_acq_deg"),
                      _ci_of(x, "acquisition_s"), _ci_of(x, "tracker_ms_per_frame"), _ci_of(x, "sim_ms_per_frame")]
                     for x in r["rows"]])
    L += _img(images, "rate", "point rate")

    # 6 ----------------------------------------------------------------------------------------
    lv = ax.get("levers")
    if lv:
        L += ["## 6. The levers: controller, recording, head ripple, scan model, attitude source, speed table", "",
              f"Each lever changed alone from {lv['scene']} as shipped (the **reference**: the paper's Algorithm 2, "
              f"the unit's true speed table, no recording), {_f(lv['duration_s'], '{:g}')} s, seeds "
              f"{', '.join(map(str, lv['seeds']))}.  Δ is the paired change against the reference (bold: outside "
              "the noise).  The world position error is the reconstructed target against the truth: the speed "
              "table moves it, the pointing hardly.", ""]
        L += _table(["lever", "CPU vs reference", "CPU per frame [ms]", "error after acq. [deg]", "Δ error after acq. [deg]",
                     "Δ error, all frames [deg]", "acquisition [s]", "Δ acquisition [s]", "world position rms [m]",
                     "Δ world position [m]"],
                    [[r["lever"], _ci(r["cost_ratio"]), _ci(r["ms_per_frame"]), _ci(r["ci"]["error_rms_acq_deg"]),
                      _delta(r["delta"]["error_rms_acq_deg"]), _delta(r["delta"]["error_rms_all_deg"]),
                      _ci(r["ci"]["acquisition_s"]), _delta(r["delta"]["acquisition_s"]), _ci(r["ci"]["recon_rms_m"]),
                      _delta(r["delta"]["recon_rms_m"])] for r in lv["rows"]])
        ref = next((r for r in lv["rows"] if r["lever"] == lv["reference"]), None)
        vals = (ref or {}).get("ci", {}).get("error_rms_acq_deg")
        if vals and vals["n"] >= 3:
            L += ["What more seeds buy: the half-width of the reference's interval of the tracking error after "
                  "acquisition, from its first n seeds (it falls about as 1/sqrt(n) once the spread is known):", ""]
            L += _table(["seeds", "half-width [deg]"], [[str(n), _f(h)] for n, h in seeds_vs_width(vals["values"])])
        L += _img(images, "levers", "levers")

    # 7 ----------------------------------------------------------------------------------------
    L += effects_section(ax.get("effects"))

    # 8 ----------------------------------------------------------------------------------------
    L += objects_section(ax.get("objects"))

    # Pareto --------------------------------------------------------------------------------------
    L += ["## Pareto front: for a target accuracy, the cheapest settings", "",
          "Per axis and scene/target, the measured settings that no other beats *beyond the noise* (better on one "
          "axis with the two intervals apart, and not worse beyond the noise on the other), then for each target "
          "accuracy the cheapest setting whose whole error interval meets it (\"-\": none measured does).  Where "
          "other settings meet the target at a cost that cannot be told apart from the cheapest one's, they are "
          "named beside it: the study does not rank them.", ""]
    cheaper = [o["optics"] for o in ax["scan"]["optics"]
               if next(r for r in o["rows"] if r["model"] == "exact")["ns_per_ray"]
               < next(r for r in o["rows"] if r["model"] == "paraxial")["ns_per_ray"]]
    if cheaper:
        L += [f"Scan model ({', '.join(cheaper)}): exact refraction is measured both cheaper per ray and exact, so "
              "no approximation of the scan model is on the front.", ""]
    names = {
        "scan": ("p95 angular error [deg]", "ns per ray"),
        "fidelity": ("|Δ tracking error rms| vs all-exact, paired [deg]", "CPU relative to all-exact"),
        "sensing": ("tracking error rms over all frames [deg]", "control latency [ms]"),
        "sensing_detect": ("detection probability (at least)", "control latency [ms]"),
        "calibration": ("speed-table error, all bytes [%]", "calibration time [s]"),
        "rate": ("tracking error rms [deg]", "tracker CPU per frame [ms]"),
        "levers": ("tracking error rms after acquisition [deg]", "CPU relative to the paper's loop"),
    }
    for axis, groups in res["pareto"].items():
        err_name, cost_name = names[axis]
        for group, g in groups.items():
            front = ", ".join(f"{p['label']} ({_f(p['cost'])}, {_f(1 - p['error'] if axis == 'sensing_detect' else p['error'])})"
                              for p in g["front"])
            L += [f"**{axis} / {group}** -- error: {err_name}; cost: {cost_name}.  Front (cost, error): {front or '-'}", ""]
            L += _table(["target", "cheapest setting", "cost", "error (upper end of its interval)",
                         "same cost within noise"],
                        [[("P >= " if axis == "sensing_detect" else "<= ") + _f(c["target"], "{:g}"), c["label"] or "-",
                          _f(c["cost"]),
                          (f"{_f(1 - c['error'])} ({_f(1 - c['error_hi'])})" if axis == "sensing_detect" and c["error"] is not None
                           else f"{_f(c['error'])} ({_f(c.get('error_hi'))})" if c["error"] is not None else "-"),
                          ", ".join(c.get("cost_ties") or []) or "-"]
                         for c in g["cheapest"]])
    L += ["## Regenerate", "", "```", COMMAND, EFFECTS_COMMAND, OBJECTS_COMMAND, "```", "",
          "Add `--scheduler tcp://HOST:8786` to run the same tasks on a Dask cluster, `--quick` for the small "
          "version; `--from-json FILE` rewrites the report and plots from saved results without rerunning.  The "
          "second and third commands run section 7 or 8 alone and write it into the existing results and page.", ""]
    return "\n".join(L)


EFFECTS_COMMAND = "foveatrack study accuracy-vs-time --axis effects --out docs --workers 2"


OBJECTS_COMMAND = "foveatrack study accuracy-vs-time --axis objects --out docs --workers 2"


def _how_run(axis: dict) -> str:
    """How a section run alone was measured (its ``run`` record), or that the whole study measured it."""
    run = axis.get("run")
    return (f"Measured by `{run['command']}` ({_f(run.get('wall_s'), '{:.0f}')} s wall on {run.get('workers', '?')} "
            f"workers, {_f(run.get('cpu_s'), '{:.0f}')} s of measured CPU; CPU: {run.get('cpu', 'not recorded')}, load "
            f"{_f(run.get('load_1min_start'), '{:.1f}')} at the start and {_f(run.get('load_1min_end'), '{:.1f}')} at the "
            "end)" if run else "Measured in the whole study's run (above)")


def effects_section(ef: dict | None) -> list[str]:
    """Section 7 of the report: each effect a scene can list, added to fig12 alone
    (:mod:`sim.study.effect_costs`); regenerated alone by :data:`EFFECTS_COMMAND`."""
    if not ef or not ef.get("rows"):
        return []
    how = _how_run(ef)
    L = ["## 7. The effects: what each costs per frame and does to fig12's tracking", "",
         f"Each effect a scene can list, added alone to {ef['scene']} at its documented default parameters "
         f"(docs/scenes.md), {_f(ef['duration_s'], '{:g}')} s, seeds {', '.join(map(str, ef['seeds']))}, paired with "
         f"fig12 as shipped (the **reference**).  CPU is the whole closed loop's per frame, as the paired ratio to "
         f"the reference's on the same seed and in ms; Δ is the paired change (bold: outside the noise).  {how}.  "
         f"Regenerate this section alone with `{EFFECTS_COMMAND}` (add `--effects NAME,...` for some of them: "
         "the other effects' rows are kept only if measured on the same CPU with the same seeds and duration; "
         "the rest of the page is rewritten unchanged from the JSON).", ""]
    excl = ef.get("excluded") or {}
    if excl:
        L += ["Not measured: " + "; ".join(f"{e} ({why})" for e, why in excl.items()) + ".", ""]
    L += _table(["effect", "CPU per frame vs reference", "CPU per frame [ms]", "Δ CPU per frame [ms]",
                 "error after acq. [deg]", "Δ error after acq. [deg]", "Δ error, all frames [deg]",
                 "acquisition [s]", "Δ acquisition [s]"],
                [[r["effect"], _ci(r["cost_ratio"]), _ci(r["ci"]["ms_per_frame"]), _delta(r["delta"]["ms_per_frame"]),
                  _ci(r["ci"]["error_rms_acq_deg"]), _delta(r["delta"]["error_rms_acq_deg"]),
                  _delta(r["delta"]["error_rms_all_deg"]), _ci(r["ci"]["acquisition_s"]),
                  _delta(r["delta"]["acquisition_s"])] for r in ef["rows"]])
    return L


def objects_section(ob: dict | None) -> list[str]:
    """Section 8 of the report: the multi-object tracker's frame against the objects and points in the
    field, and what it tracks (:mod:`sim.study.sky_objects`); regenerated alone by :data:`OBJECTS_COMMAND`."""
    if not ob or not ob.get("rows"):
        return []
    seeds = ob["rows"][0]["seeds"]
    L = ["## 8. The sky: the multi-object tracker's frame against objects and points", "",
         f"The sky scenes (issue 28; docs/sky-tracks.md) with the flock cut or added, and the swarm scanned by a "
         f"Horizon instead of its Mid-40, {_f(ob['duration_s'], '{:g}')} s, {len(seeds)} seeds each (each seed its own "
         f"world).  CPU is the worker's per frame of the whole closed loop without recording; of it the ray casting "
         f"with the effects and the tracker (the loop's stage clocks).  What it tracks: the share of drones confirmed "
         f"within 2 s of entering the field, id switches and false drone tracks per run, the mean GOSPA "
         f"(c = 5 m).  {_how_run(ob)}.  Regenerate this section alone with `{OBJECTS_COMMAND}`.", ""]
    L += _table(["case", "objects", "points a frame", "CPU per frame [ms]", "x real time", "ray casting [ms]",
                 "tracker [ms]", "confirmed within 2 s", "id switches", "false drone tracks", "GOSPA [m]"],
                [[r["case"], _f(r["ci"]["objects"]["mean"], "{:.0f}"), _f(r["ci"]["points_per_frame"]["mean"], "{:.0f}"),
                  _ci(r["ci"]["ms_per_frame"]), _f(r.get("x_real_time"), "{:.0f}"), _ci(r["ci"]["cast_ms_per_frame"]),
                  _ci(r["ci"]["tracker_ms_per_frame"]), _ci(r["ci"]["confirmed_within_2s_share"]),
                  _ci(r["ci"]["id_switches"]), _ci(r["ci"]["false_drone_tracks"]), _ci(r["ci"]["gospa_mean_m"])]
                 for r in ob["rows"]])
    return L


__all__ = ["write_report", "headlines", "effects_section", "objects_section", "COMMAND", "EFFECTS_COMMAND",
           "OBJECTS_COMMAND", "TARGETS"]


def _orbit_m(target: str) -> float:
    """Radius of a sensing target's circle [m], from the scene the study runs (not a copy of it)."""
    return target_scene(target).targets[0].trajectory.radius_m
