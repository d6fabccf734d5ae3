"""Tracking-error regression tests (issue 5): pinned scenes against a committed baseline.

Each pinned scene (tests/regression/cases.py: every shipped scene with a target, the hard ones
included) is run in the closed loop and its metrics (sim.summary.summarize: angular error
rms/p95/max after acquisition, acquisition time, reconstruction error, detections, points on
target) are compared with tests/regression/baseline.json.  A metric that got worse than its
baseline by more than its tolerance (``abs + rel * |baseline|``, see cases.TOLERANCES) fails the
test; the comparison table is printed either way.  Regenerate the baseline deliberately with
``python scripts/update_regression_baseline.py`` (docs/tracker.md).
"""

import json

import pytest

from cases import BASELINE, CASES, TOLERANCES, run_case
from foveatrack.metrics import compare_to_baseline

_BASE = json.loads(BASELINE.read_text())["scenes"]


def test_baseline_pins_every_case():
    assert set(_BASE) == set(CASES)


@pytest.mark.parametrize("name", sorted(CASES))
def test_scene_is_no_worse_than_its_baseline(name):
    metrics = run_case(name)
    base = _BASE[name]
    assert metrics["duration_s"] == base["duration_s"], "the pinned duration changed: regenerate the baseline"
    table, failures = compare_to_baseline(metrics, base, TOLERANCES)
    print(f"\n{name}\n{table}")
    assert not failures, f"{name} got worse than its baseline:\n" + "\n".join(failures)


def test_the_comparison_catches_a_worse_run():
    # the check itself can fail: a 20 % worse rms error on fig12 is flagged
    base = _BASE["fig12-tracking"]
    worse = json.loads(json.dumps(base))
    worse["tracking_error_deg"]["rms"] *= 1.2
    _, failures = compare_to_baseline(worse, base, TOLERANCES)
    assert any("tracking_error_deg.rms" in f for f in failures)
