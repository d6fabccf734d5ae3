"""Regenerate tests/regression/baseline.json: the tracking-error regression baseline.

Run deliberately, after a change that is *meant* to change tracking (a better controller, a new
effect in a pinned scene), and commit the new file with a message saying why the numbers moved::

    python scripts/update_regression_baseline.py            # all pinned scenes
    python scripts/update_regression_baseline.py --check    # print the comparison only, write nothing
    python scripts/update_regression_baseline.py --scene noisy-link   # only the named scene(s); the
                                                            # others keep their stored values (another
                                                            # machine's last digits stay where they are)
    python scripts/update_regression_baseline.py --monte-carlo [--seeds N] [--scheduler tcp://HOST:8786]
                                                            # tests/regression/baseline_mc.json: each
                                                            # scene over N seeds (default 8), mean and spread
    python scripts/update_regression_baseline.py --sky [--seeds N]
                                                            # tests/regression/baseline_sky_mc.json: the sky
                                                            # scenes' totals over N seeds (default 8)

The pinned scenes, their durations and the tolerances live in tests/regression/cases.py.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "regression"))

from cases import (BASELINE, BASELINE_MC, BASELINE_SKY_MC, CASES, MC_SEEDS, SKY_CASES, SKY_TOLERANCES,  # noqa: E402
                   TOLERANCES, monte_carlo, run_case, sky_monte_carlo)

from foveatrack.metrics import compare_spread_to_baseline, compare_to_baseline  # noqa: E402


# the two Monte Carlo baselines: (file, scenes, runner, tolerances, format, what a scene's entry holds, flag)
MC_KINDS = {
    "pinned": (BASELINE_MC, CASES, monte_carlo, TOLERANCES, "foveatrack-regression-monte-carlo",
               "per pinned scene and flattened metric of sim.summary.summarize", "--monte-carlo"),
    "sky": (BASELINE_SKY_MC, SKY_CASES, sky_monte_carlo, SKY_TOLERANCES, "foveatrack-regression-sky-monte-carlo",
            "per sky scene and total of sim.sky_summary.sky_totals", "--sky"),
}


def update_monte_carlo(args, kind: str) -> int:
    from sim.monte_carlo import seeds_for
    from sim.sweep import make_executor

    path, cases, runner, tolerances, fmt, holds, flag = MC_KINDS[kind]
    seeds = seeds_for(args.seeds)
    old = json.loads(path.read_text()) if path.exists() else None
    names = sorted(args.scene or cases)
    if args.scene and (old is None or old["seeds"] != seeds):
        raise SystemExit(f"--scene with {flag} needs a baseline over the same seeds to keep the other scenes")
    with make_executor(args.scheduler, args.workers) as ex:
        spreads = runner(names, seeds, ex, progress=True)
    for name, spread in spreads.items():
        if old is not None and name in old["scenes"]:
            table, failures = compare_spread_to_baseline(spread, old["scenes"][name], tolerances)
            print(f"== {name} over {len(seeds)} seeds (baseline: {len(old['seeds'])})"
                  f"{'  (WORSE: ' + '; '.join(failures) + ')' if failures else ''}\n{table}\n")
    if args.check:
        return 0
    if args.scene:   # the other scenes keep their stored spreads
        spreads = {**old["scenes"], **spreads}
    path.write_text(json.dumps({
        "format": fmt, "version": 1,
        "note": f"{holds}: mean, sample sd, runs with a value and runs without, over the seeds below; "
                f"regenerate with python scripts/update_regression_baseline.py {flag} (tolerances: "
                "tests/regression/cases.py)",
        "seeds": seeds, "scenes": spreads}, indent=1, sort_keys=True) + "\n")
    print(f"wrote {path}")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--check", action="store_true", help="compare with the current baseline; write nothing")
    ap.add_argument("--monte-carlo", action="store_true", help="the Monte Carlo baseline (each scene over --seeds)")
    ap.add_argument("--sky", action="store_true", help="the sky scenes' Monte Carlo baseline (their totals over --seeds)")
    ap.add_argument("--seeds", type=int, default=MC_SEEDS, help=f"seeds per scene (default {MC_SEEDS})")
    ap.add_argument("--workers", type=int, default=None, help="local worker processes (default: one per core)")
    ap.add_argument("--scheduler", default=None, help="a Dask scheduler, tcp://HOST:8786, instead of local processes")
    ap.add_argument("--scene", action="append", choices=sorted({**CASES, **SKY_CASES}), default=None,
                    help="regenerate only this scene (repeatable); the others keep their stored values")
    args = ap.parse_args(argv)
    kind = "sky" if args.sky else "pinned" if args.monte_carlo else None
    allowed, what = (MC_KINDS[kind][1], f"a scene of {MC_KINDS[kind][6]}") if kind else (CASES, "a pinned scene")
    if args.scene and not set(args.scene) <= set(allowed):
        raise SystemExit(f"--scene: {', '.join(sorted(set(args.scene) - set(allowed)))} is not {what}")
    if kind:
        return update_monte_carlo(args, kind)
    old = json.loads(BASELINE.read_text())["scenes"] if BASELINE.exists() else {}
    scenes = {name: old[name] for name in CASES if args.scene and name not in args.scene and name in old}
    for name in CASES:
        if name in scenes:
            continue
        m = run_case(name)
        scenes[name] = m
        if name in old:
            table, failures = compare_to_baseline(m, old[name], TOLERANCES)
            print(f"== {name}{'  (WORSE: ' + '; '.join(failures) + ')' if failures else ''}\n{table}\n")
        else:
            print(f"== {name}: new\n")
    if args.check:
        return 0
    BASELINE.write_text(json.dumps({
        "format": "foveatrack-regression-baseline", "version": 1,
        "note": "metrics of sim.summary.summarize per pinned scene; regenerate with "
                "python scripts/update_regression_baseline.py (tolerances: tests/regression/cases.py)",
        "scenes": scenes}, indent=1, sort_keys=True) + "\n")
    print(f"wrote {BASELINE}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
