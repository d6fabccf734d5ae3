"""Run scenes with the multi-object tracker ([tracker.sky], added here if the scene lacks it) over
seeds and print the issue-28 figures: per drone the time to a confirmed track after entering the
lidar's field (and the earliest the scan's rays on it allowed:
:func:`sim.sky_summary.scan_allows_confirm_s`), id switches, continuity, share of time in the fovea
and the longest revisit gap (and the shortest the head's speed allowed:
:func:`sim.sky_bounds.head_allows_revisit_s`); false confirmed drone tracks per hour; GOSPA; and the
drone/bird/clutter confusion matrix of the confirmed tracks.  ``--markdown PATH`` also writes them as
a docs page.

    .venv/bin/python scripts/sky_tracks_report.py scenes/two-drones-crossing.toml --seeds 8

The figures of one run are :func:`sim.sky_summary.sky_run_figures`' (what ``foveatrack simulate``
prints for such a run).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import re
import sys
import time
from collections import Counter
from collections.abc import Mapping

import numpy as np

from foveatrack.config_util import check_output_file, positive_arg
from foveatrack.errors import UserError
from foveatrack.sky.controller import sky_configs_from_mapping
from sim.loop import ClosedLoop
from sim.scene import load_scene, with_run_overrides
from sim.sky_summary import GAP_REASONS, LABELS, REVISIT_S, TRUTH_CLASSES, sky_run_figures, within_bound


def run_one(scene):
    loop = ClosedLoop(scene)
    t0 = time.perf_counter()
    log = loop.run()
    wall = time.perf_counter() - t0
    m, g, confusion = sky_run_figures(loop, log)
    return m, g, confusion, wall, len(log["t_end_s"])


def _median_max(values) -> str:
    """``median / max`` of the numbers that are (NaN: none measured), ``- / -`` if none are."""
    v = [x for x in values if x is not None and not math.isnan(x)]
    return f"{np.median(v):.1f} / {max(v):.1f}" if v else "- / -"


def run_longest_gap(m) -> float | None:
    """A run's longest revisit gap over its drones; None where a drone in the field was never tracked
    (never revisited: the run does not meet the revisit time whatever the others did)."""
    gaps = [r.get("longest_revisit_gap_s", 0.0) for r in m["drones"].values()]
    return None if any(g is None for g in gaps) else max(gaps, default=0.0)


def summary_row(name, rows) -> str:
    """One scene over all its runs: the issue-28 figures that decide, with false drone tracks per hour
    of run by what they were near."""
    hours = sum(m["hours"] for _, m, *_ in rows)
    drones = [r for _, m, *_ in rows for r in m["drones"].values()]
    within, scan, scan_cold = (within_bound(drones, k) for k in ("time_to_confirm_s", "scan_allows_confirm_s",
                                                                 "scan_allows_confirm_no_warmup_s"))
    # drone by drone: a count of each can agree while the drones differ (a track of objects that
    # held other returns too can be confirmed before the drone's own rays allow it)
    both = within_bound([r for r in drones if within_bound([r], "scan_allows_confirm_s")])
    gaps = [r.get("longest_revisit_gap_s") for r in drones]      # _median_max leaves out the unmeasured
    # per run: every drone's longest gap within the revisit time (a drone no track followed is not),
    # and whether the head's speed allowed it
    run_gap = [run_longest_gap(m) for _, m, *_ in rows]
    run_bound = [m.get("head_allows_revisit_s") for _, m, *_ in rows]
    met = [g is not None and g <= REVISIT_S + 1e-9 for g in run_gap]
    allowed = [b is None or b <= REVISIT_S + 1e-9 for b in run_bound]
    bounds = [b for b in run_bound if b is not None]
    causes = Counter()
    for _, m, *_ in rows:
        causes.update(m["false_causes"])
    per_h = " / ".join(f"{causes[c]} ({causes[c] / hours:.0f})" for c in ("bird", "clutter", "drone"))
    return (f"| {name} | {len(rows)} | {hours:.2f} | {len(drones)} | {within} ({scan}; {scan_cold}; {both}) | "
            f"{sum(r['id_switches'] for r in drones)} | {_median_max(gaps)} ({_median_max(bounds)}) | "
            f"{sum(met)} ({sum(allowed)}; {sum(a and b for a, b in zip(met, allowed))}) | {per_h} |")


def gap_row(name, rows) -> str:
    """One scene over all its runs: the frames of its drones' longest revisit gaps, by what the fovea
    did (:func:`sim.sky_summary.gap_reasons`)."""
    c = Counter()
    for _, m, *_ in rows:
        for r in m["gap_reasons"].values():
            c.update(r)
    n = sum(c.values())
    return f"| {name} | {n} | " + " | ".join(f"{c[k]} ({100 * c[k] / n if n else 0:.0f} %)" for k in GAP_REASONS) + " |"


GAP_HEAD = ("| scene | frames of the longest gaps | " + " | ".join(GAP_REASONS) + " |\n"
            + "|---" * (len(GAP_REASONS) + 2) + "|")


SUMMARY_HEAD = ("| scene | runs | scene-hours | drones | confirmed within 2 s (the scan's rays allowed it; without "
                "the warm-up; both confirmed and allowed) | id switches | longest revisit gap, median / max [s] (the run's least the "
                "head's speed allowed) | runs with every gap within 3 s (runs the head allowed it; both) | "
                "false drone tracks (per hour) near a bird / a tree or clutter / a drone |\n"
                "|---|---|---|---|---|---|---|---|---|")


def _at_least_one(text: str) -> int:
    """--seeds: an integer >= 1 (none would leave the figures nothing to divide by)."""
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {n}")
    return n


def _set_item(text: str) -> tuple[tuple[str, ...], bool | int | float]:
    """--set KEY=VALUE: the key's path (classifier.min_hits=6: a key of a sub-table) and the value, true
    or false, an integer or a finite number (the [tracker.sky] keys are all numbers or booleans)."""
    key, eq, value = text.partition("=")
    path = tuple(key.split("."))
    if not eq or not all(path):
        raise argparse.ArgumentTypeError(f"{text!r}: expected KEY=VALUE, e.g. warmup_s=0.8 or "
                                         "attention.revisit_s=2.8")
    if value in ("true", "false"):
        return path, value == "true"
    if value.lstrip("-").isdigit():
        return path, int(value)
    try:
        v = float(value)
    except ValueError:
        v = math.nan
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"{text!r}: {value!r} is not true, false or a finite number")
    return path, v


def build_parser() -> argparse.ArgumentParser:
    # the prog named as the script, also when main() is called from elsewhere (the tests)
    # the docstring's first paragraph, its reST markup (:func:`x`, ``x``) read as plain text in a terminal
    description = re.sub(r":\w+:`([^`]*)`", r"\1", __doc__.split("\n\n")[0]).replace("``", "")
    ap = argparse.ArgumentParser(prog=os.path.basename(__file__), description=description)
    ap.add_argument("scenes", nargs="+", metavar="SCENE",
                    help="scene files, e.g. scenes/two-drones-crossing.toml, run one after another")
    ap.add_argument("--seeds", type=_at_least_one, default=8,
                    help="runs of each scene, each seed its own world (default 8, at least 1)")
    ap.add_argument("--first-seed", type=int, default=0,
                    help="seeds from the scene's own plus this (default 0): tune on others than you report")
    ap.add_argument("--duration", type=positive_arg, default=None, help="override the scenes' duration [s]")
    ap.add_argument("--markdown", default=None, metavar="PATH",
                    help="also write what is printed to this file, a Markdown page (its directory must exist)")
    ap.add_argument("--summary-only", action="store_true",
                    help="leave out the per-seed tables: print the summary and where the longest revisit gaps "
                         "went (a line per scene each) and the confusion matrix of all the scenes (for long "
                         "runs: --seeds 180 is a scene-hour of a 20 s scene)")
    ap.add_argument("--set", nargs="*", default=[], type=_set_item, metavar="KEY=VALUE",
                    help="[tracker.sky] keys to set for the run (numbers, true or false), e.g. warmup_s=0.8, "
                         "warmup_replay=false or classifier.drone_after_frames=10")
    return ap


def main(argv=None) -> int:
    ap = build_parser()
    a = ap.parse_args(argv)
    try:
        return report(a)
    except UserError as exc:     # as the foveatrack command reports one: a line, no traceback
        print(f"{ap.prog}: error: {exc}", file=sys.stderr)
        return 2


def scene_and_table(path: str, a: argparse.Namespace):
    """The scene at ``path`` and its [tracker] table with [tracker.sky] and the --set keys, checked (the
    seeds it will run, the sky table's keys and values) so that a mistake stops the report before a run."""
    base = load_scene(path)
    if base.seed + a.first_seed < 0:
        raise UserError(f"--first-seed {a.first_seed}: {path}'s seed {base.seed} plus it is below 0")
    duration = base.duration_s if a.duration is None else a.duration
    if round(duration * base.tracker.rate_hz) < 1:      # no frame: nothing to divide the figures by
        given = "" if a.duration is None else "--duration: "
        raise UserError(f"{given}{path}: duration {duration:g} s is shorter than one tracker frame "
                        f"({1 / base.tracker.rate_hz:g} s)")
    sky = dict(base.tracker_table.get("sky", {}))
    for (*tables, k), v in a.set:          # classifier.min_hits=6: a key of a sub-table
        t = sky
        for name in tables:
            if not isinstance(t.get(name, {}), Mapping):
                raise UserError(f"--set {'.'.join((*tables, k))}={v}: {name} is a key, not a table")
            t[name] = t = dict(t.get(name, {}))
        t[k] = v
    sky_configs_from_mapping(sky, f"{path} [tracker.sky]")     # what ClosedLoop builds from it
    return base, {**base.tracker_table, "sky": sky}


def check_markdown(path: str) -> None:
    """--markdown PATH is written after every run: that it can be is checked before the first."""
    check_output_file(path, "--markdown")        # a directory, a missing or unwritable directory
    existed = os.path.exists(path)
    try:            # opened as it will be (a permission, a read-only or special file system), left as it was
        with open(path, "a"):
            pass
    except OSError as exc:
        raise UserError(f"--markdown {path}: cannot write it ({exc.strerror or exc})") from None
    if not existed:
        os.remove(path)


def report(a: argparse.Namespace) -> int:
    if a.markdown:
        check_markdown(a.markdown)
    scenes = [scene_and_table(path, a) for path in a.scenes]    # every scene before any run
    lines = []
    summary = []
    gap_rows = []
    total_conf = Counter()
    for base, table in scenes:
        rows = []
        for s in range(a.first_seed, a.first_seed + a.seeds):
            # rebuilt from the scene's text with the seed and duration, so that what is drawn when
            # the scene is loaded follows them: the flocks, the crowns' sway (drawn over the run: a
            # crown held still past the scene's own 20 s in an hour's run), a manual flight's path
            scene = dataclasses.replace(with_run_overrides(base, a.duration, base.seed + s), tracker_table=table)
            m, g, conf, wall, T = run_one(scene)
            total_conf.update(conf)
            rows.append((scene.seed, m, g, wall, T))
            print(f"{base.name} seed {scene.seed}: {T} frames in {wall:.1f} s; GOSPA mean {g:.2f} m; "
                  f"false drone tracks {len(m['false_drone_tracks'])}", file=sys.stderr)
        summary.append(summary_row(base.name, rows))
        gap_rows.append(gap_row(base.name, rows))
        if a.summary_only:
            continue
        lines.append(f"## {base.name} ({a.seeds} seeds)\n")
        lines.append("| seed | drone | time to confirm [s] | the scan's rays allowed [s] (without the warm-up) | "
                     "time to the drone label [s] | id switches | continuity | fovea share | longest revisit gap "
                     "[s] | the head allowed its first gap [s] |")
        lines.append("|---|---|---|---|---|---|---|---|---|---|")
        for seed, m, g, wall, T in rows:
            for d, r in m["drones"].items():
                ttc, ttl, sb, sb0 = ("never" if r[k] is None else f"{r[k]:.1f}" for k in (
                    "time_to_confirm_s", "time_to_drone_label_s", "scan_allows_confirm_s",
                    "scan_allows_confirm_no_warmup_s"))
                lines.append(f"| {seed} | {d} | {ttc} | {sb} ({sb0}) | {ttl} | {r['id_switches']} | "
                             f"{r['continuity']:.2f} | "
                             f"{r.get('fovea_share', math.nan):.2f} | "
                             + ("never tracked" if r.get("longest_revisit_gap_s", 0.0) is None
                                else f"{r.get('longest_revisit_gap_s', math.nan):.1f}") + " | "
                             + ("-" if r.get("head_allows_acquire_s") is None else f"{r['head_allows_acquire_s']:.1f}")
                             + " |")
        lines.append("")
        lines.append("| seed | false confirmed drone tracks | per hour | mean GOSPA (c = 5 m, p = 2) [m] | "
                     "longest revisit gap (the head's speed allowed) [s] | wall [s] |")
        lines.append("|---|---|---|---|---|---|")
        for seed, m, g, wall, T in rows:
            gap = run_longest_gap(m)
            b = m.get("head_allows_revisit_s")
            lines.append(f"| {seed} | {len(m['false_drone_tracks'])} | {m['false_drone_tracks_per_hour']:.0f} | "
                         f"{g:.2f} | {'a drone never tracked' if gap is None else f'{gap:.1f}'} "
                         f"({'-' if b is None else f'{b:.1f}'}) | {wall:.1f} |")
        lines.append("")
    lines[:0] = ["## Summary\n", SUMMARY_HEAD, *summary, "",
                 "Where each drone's longest revisit gap went, frame by frame (what the fovea did then):\n",
                 GAP_HEAD, *gap_rows, ""]
    lines.append("## Confusion matrix of the confirmed tracks (rows: truth, columns: the track's last label)\n")
    lines.append("| truth \\ label | " + " | ".join(LABELS) + " |")
    lines.append("|---|" + "---|" * len(LABELS))
    for c in TRUTH_CLASSES:
        lines.append(f"| {c} | " + " | ".join(str(total_conf[(c, l)]) for l in LABELS) + " |")
    text = "\n".join(lines) + "\n"
    print(text)
    if a.markdown:
        try:
            with open(a.markdown, "w") as f:
                f.write(text)
        except OSError as exc:     # a full disk, say: the report is on stdout above
            raise UserError(f"--markdown {a.markdown}: {exc.strerror or exc} (the report is printed above)") from None
    return 0


if __name__ == "__main__":
    sys.exit(main())
