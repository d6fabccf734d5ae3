"""Regenerate tests/regression/baseline.json: the tracking-error regression baseline.

Run deliberately, after a change that is *meant* to change tracking (a better controller, a new
effect in a pinned scene), and commit the new file with a message saying why the numbers moved::

    python scripts/update_regression_baseline.py            # all pinned scenes
    python scripts/update_regression_baseline.py --check    # print the comparison only, write nothing

The pinned scenes, their durations and the tolerances live in tests/regression/cases.py.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "regression"))

from cases import BASELINE, CASES, TOLERANCES, run_case  # noqa: E402

from foveatrack.metrics import compare_to_baseline  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--check", action="store_true", help="compare with the current baseline; write nothing")
    args = ap.parse_args(argv)
    old = json.loads(BASELINE.read_text())["scenes"] if BASELINE.exists() else {}
    scenes = {}
    for name in CASES:
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
