"""Pieces of the study checked on their own: Pareto front, table errors, interpolation, CLI errors."""

import math

import numpy as np
import pytest

from foveatrack.cli import main
from foveatrack.speed_table import AxisTable, SpeedEntry, SpeedTable
from sim.study.pareto import cheapest_for, pareto_front


def _pts(rng, n):
    return [{"group": "g", "label": str(i), "cost": float(c), "error": float(e)}
            for i, (c, e) in enumerate(rng.integers(0, 8, size=(n, 2)))]


@pytest.mark.parametrize("seed", range(20))
def test_pareto_front_is_exactly_the_non_dominated_set(seed):
    pts = _pts(np.random.default_rng(seed), 15)
    front = pareto_front(pts)

    def dominates(q, p):
        return q["cost"] <= p["cost"] and q["error"] <= p["error"] and (q["cost"], q["error"]) != (p["cost"], p["error"])

    for p in pts:
        assert (p in front) == (not any(dominates(q, p) for q in pts))
    assert [p["cost"] for p in front] == sorted(p["cost"] for p in front)


@pytest.mark.parametrize("seed", range(20))
def test_cheapest_for_a_target_is_the_brute_force_minimum(seed):
    pts = _pts(np.random.default_rng(seed), 10)
    for target in range(-1, 9):
        got = cheapest_for(pts, target)
        ok = [p for p in pts if p["error"] <= target]
        if not ok:
            assert got is None
        else:
            assert got["error"] <= target and got["cost"] == min(p["cost"] for p in ok)
            assert got in pareto_front(pts)   # the cheapest meeting a target is always on the front


def _iv(c, ch, e, eh, label):
    return {"group": "g", "label": label, "cost": c, "cost_lo": c - ch, "cost_hi": c + ch,
            "error": e, "error_lo": e - eh, "error_hi": e + eh}


def test_within_the_noise_nothing_is_ranked():
    """Two settings whose cost and error intervals overlap are both on the front; a target is met only
    by the upper end of an error interval; a cost tie is named, not ranked."""
    from sim.study.pareto import cost_ties

    a = _iv(1.00, 0.10, 0.50, 0.20, "a")
    b = _iv(1.05, 0.10, 0.40, 0.20, "b")      # cheaper/better than neither beyond the noise
    c = _iv(3.00, 0.10, 0.45, 0.01, "c")      # clearly dearer than a, error within a's: dominated
    front = pareto_front([a, b, c])
    assert [p["label"] for p in front] == ["a", "b"]
    assert cheapest_for([a, b, c], 0.40) is None            # upper ends: a 0.70, b 0.60, c 0.46
    assert cheapest_for([a, b, c], 0.55)["label"] == "c"   # a's and b's means meet it, their intervals do not
    assert cheapest_for([a, b, c], 0.65)["label"] == "b"
    assert cheapest_for([a, b, c], 0.70)["label"] == "a"
    assert [p["label"] for p in cost_ties([a, b, c], a, 0.70)] == ["b"]


@pytest.mark.parametrize("n", [2, 3, 5, 8])
def test_interval_is_the_student_t_interval(n):
    from scipy import stats

    from sim.study.stats import abs_bounds, excludes_zero, interval, paired_delta

    x = np.random.default_rng(n).normal(3.0, 0.7, n)
    iv = interval(x)
    lo, hi = stats.t.interval(0.95, n - 1, loc=np.mean(x), scale=stats.sem(x))
    assert iv["lo"] == pytest.approx(lo, rel=1e-12) and iv["hi"] == pytest.approx(hi, rel=1e-12)
    assert iv["values"] == list(x)
    d = paired_delta({s: v for s, v in enumerate(x)}, {s: v for s, v in enumerate(x)})
    assert d["mean"] == 0.0 and not excludes_zero(d) and abs_bounds(d) == (0.0, 0.0)
    assert excludes_zero(paired_delta({s: v + 1 for s, v in enumerate(x)}, {s: v for s, v in enumerate(x)}))
    assert interval([1.0])["half"] is None and not excludes_zero(interval([1.0]))
    assert interval([None, float("nan")]) is None


def test_pareto_ignores_points_without_a_number():
    pts = [{"label": "a", "cost": None, "error": 0.0}, {"label": "b", "cost": 1.0, "error": math.nan},
           {"label": "c", "cost": 2.0, "error": 1.0}]
    assert [p["label"] for p in pareto_front(pts)] == ["c"]


def _table(f_pan, f_tilt):
    from foveatrack.speed_table import TURBO

    def axis(name, f):
        bs = list(range(64)) + ([TURBO] if name == "pan" else [])
        return AxisTable(name, tuple(SpeedEntry(b, f(b), 0.0, True) for b in bs))
    return SpeedTable(axis("pan", f_pan), axis("tilt", f_tilt))


def test_table_errors_measure_a_known_scale_error():
    from sim.study.calibration_time import table_errors

    truth = _table(lambda b: 0.2 * b, lambda b: 0.03 * b)
    scaled = _table(lambda b: 0.2 * b * 1.05, lambda b: 0.03 * b)   # pan 5 % fast, tilt exact
    e = table_errors(truth, truth, {"pan": (8,), "tilt": (8,)})
    assert e["table_err_all_pct"] == 0 and e["table_abs_pan_deg_s"] == 0 and e["unknown_bytes"] == 0
    e = table_errors(scaled, truth, {"pan": (32,), "tilt": ()})
    assert e["table_err_measured_pct"] == pytest.approx(5.0)
    assert e["table_err_max_pct"] == pytest.approx(5.0)
    moving_pan = [b for b in range(1, 64) if b >= 0.1 * 63]
    moving = len(moving_pan) * 2
    assert e["table_err_all_pct"] == pytest.approx(5.0 * math.sqrt(len(moving_pan) / moving))
    assert e["table_abs_pan_deg_s"] == pytest.approx(math.sqrt(np.mean([(0.01 * b) ** 2 for b in range(1, 64)])))


def test_interpolating_every_point_is_the_exact_model():
    from sim.scan.model import ScanModel
    from sim.scan.presets import HORIZON
    from sim.study.scan_fidelity import interpolated_exact

    m = ScanModel(HORIZON)
    revs = m.prism_revs(1000, 600)
    ch = m.channels(1000, 600)
    d, _ = m.directions_from_revs(revs, ch)
    np.testing.assert_allclose(interpolated_exact(m, revs, ch, 1, HORIZON.channels), d, atol=1e-15)
    # knots are exact at every step-th point of each channel
    d4 = interpolated_exact(m, revs, ch, 4, HORIZON.channels)
    for c in range(HORIZON.channels):
        idx = np.arange(c, 600, HORIZON.channels)[::4]
        np.testing.assert_allclose(d4[idx], d[idx], atol=1e-15)


def test_user_errors(tmp_path, capsys):
    assert main(["study", "accuracy-vs-time", "--out", str(tmp_path), "--workers", "0"]) == 2
    assert "--workers 0" in capsys.readouterr().err
    assert main(["study", "accuracy-vs-time", "--out", str(tmp_path), "--from-json", str(tmp_path / "nope.json")]) == 2
    assert "no such file" in capsys.readouterr().err
    (tmp_path / "x.json").write_text("[1, 2]")
    assert main(["study", "accuracy-vs-time", "--out", str(tmp_path), "--from-json", str(tmp_path / "x.json")]) == 2
    assert "not a study result" in capsys.readouterr().err


def test_a_study_does_not_replace_the_study_its_out_holds_unasked(tmp_path, capsys):
    # before: a quick study into docs/ replaced the shipped 20-minute report without a word (a user's
    # audit); the report rewritten from its own JSON, and --axis (one section), still go ahead
    held = tmp_path / "accuracy-vs-time.json"
    held.write_text('{"meta": {"command": "foveatrack study accuracy-vs-time --out docs"}, "results": {}}')
    before = held.read_bytes()
    for argv in (["--quick"], ["--from-json", str(tmp_path / "other.json")]):
        assert main(["study", "accuracy-vs-time", "--out", str(tmp_path), *argv, "--no-progress"]) == 2
        err = capsys.readouterr().err
        assert "holds a study" in err and "made by `foveatrack study accuracy-vs-time --out docs`" in err
        assert "--overwrite" in err
    assert held.read_bytes() == before


def test_a_run_that_compiled_a_kernel_is_timed_again(monkeypatch):
    # a fresh install's first quick study timed numba's compiler inside its runs (a user's audit:
    # 'all-cheap' at 16 +- 199 times all-exact's CPU): a run that compiled is run again, and timed so
    from sim.study import common

    seen = []
    counts = iter([0, 1, 1, 1])            # the first run compiled; the second did not

    monkeypatch.setattr(common, "compiles_so_far", lambda: next(counts))
    monkeypatch.setattr(common, "_run_loop_once", lambda *a: seen.append(a) or {"cpu_s": float(len(seen))})
    assert common.run_loop("scene")["cpu_s"] == 2.0 and len(seen) == 2
    seen.clear()
    counts = iter([1, 1])
    monkeypatch.setattr(common, "compiles_so_far", lambda: next(counts))
    assert common.run_loop("scene")["cpu_s"] == 1.0 and len(seen) == 1      # nothing compiled: once


def test_the_compile_count_sees_a_numba_compile():
    from numba import njit

    from sim.study.common import compiles_so_far

    before = compiles_so_far()

    @njit
    def fresh(x):            # not cached: compiled here, at its first call
        return x + 1

    assert fresh(1) == 2 and compiles_so_far() == before + 1
    assert fresh(2) == 3 and compiles_so_far() == before + 1      # the same types: no compile
