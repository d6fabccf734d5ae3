"""The accuracy-vs-time study: a --quick run through the CLI, and the defining properties of the
numbers its report prints (each recomputed by an independent route)."""

import json
import math

import numpy as np
import pytest

from foveatrack.cli import main

SECTIONS = ("## 1. Scan model fidelity", "## 2. Simulation fidelity", "## 3. Sensing time",
            "## 4. Calibration time", "## 5. Point rate / channels", "## 6. The levers", "## 7. The effects",
            "## Pareto front: for a target accuracy, the cheapest settings", "## Regenerate")


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("study")
    assert main(["study", "accuracy-vs-time", "--quick", "--out", str(out), "--workers", "2", "--no-progress"]) == 0
    saved = json.loads((out / "accuracy-vs-time.json").read_text())
    return out, saved["results"], saved["meta"]


def test_cli_writes_report_plots_and_json(quick):
    out, res, meta = quick
    text = (out / "accuracy-vs-time.md").read_text()
    for s in SECTIONS:
        assert s in text
    pngs = sorted(p.name for p in (out / "img" / "study").glob("*.png"))
    assert len(pngs) == 7
    for name in pngs:   # every plot is linked from the report, relative to it
        assert f"](img/study/{name})" in text
        assert (out / "img" / "study" / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "float32 is not offered" in text
    assert res["size"] == "quick" and meta["command"].startswith("foveatrack study accuracy-vs-time --quick")
    assert meta["cpu"] and meta["cpu"] in text   # costs in seconds name the machine that measured them


def test_report_is_a_function_of_the_saved_results(quick, tmp_path):
    out, _, _ = quick
    assert main(["study", "accuracy-vs-time", "--out", str(tmp_path), "--from-json",
                 str(out / "accuracy-vs-time.json")]) == 0
    assert (tmp_path / "accuracy-vs-time.md").read_text() == (out / "accuracy-vs-time.md").read_text()


def _angle_deg(a, b):
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.sum(a * b, axis=1)))


def test_paraxial_error_is_the_direction_difference_measured_independently(quick):
    """The report's paraxial error = angle between two independently built scans of the same points."""
    from sim.scan.model import ScanModel
    from sim.scan.presets import PRESETS

    _, res, _ = quick
    for o in res["axes"]["scan"]["optics"]:
        optics = PRESETS[o["optics"]]
        ex = ScanModel(optics, "exact").scan(o["k0"], o["rays"])
        pa = ScanModel(optics, "paraxial").scan(o["k0"], o["rays"])
        ok = ex.valid
        err = _angle_deg(pa.direction[ok], ex.direction[ok])
        row = {r["model"]: r for r in o["rows"]}
        assert row["exact"]["max_deg"] == 0.0
        assert row["paraxial"]["rms_deg"] == pytest.approx(math.sqrt(np.mean(err ** 2)), rel=1e-9)
        assert row["paraxial"]["p95_deg"] == pytest.approx(np.percentile(err, 95), rel=1e-9)
        assert row["paraxial"]["max_deg"] == pytest.approx(err.max(), rel=1e-9)
        assert o["valid_rays"] == int(ok.sum())


def test_fidelity_reference_deviates_from_itself_by_nothing(quick):
    _, res, _ = quick
    for f in res["axes"]["fidelity"].values():
        ref = next(r for r in f["rows"] if r["setting"] == f["reference"])
        assert ref["d_error_rms_all_deg"] == 0.0 and ref["d_points_on_target_per_frame"] == 0.0
        d = ref["delta"]["error_rms_all_deg"]
        assert d["mean"] == 0.0 and d["half"] == 0.0 and d["n"] == len(f["seeds"]) >= 2
        assert ref["cost_ratio"]["values"] == [1.0] * len(f["seeds"])
        for r in f["rows"]:     # every setting's per-seed values are kept, in seed order
            assert len(r["ci"]["error_rms_all_deg"]["values"]) == len(f["seeds"])


def test_sensing_numbers_obey_their_definitions(quick):
    """P(detect) = detections / frames in FoV; the bearing's age at the head lies between the wire time
    (a point at the very end of the window) and one window more."""
    from sim.study.sensing import target_scene

    _, res, _ = quick
    for target, t in res["axes"]["sensing"]["targets"].items():
        g = target_scene(target).gimbal
        floor = g.send_delay_s + 70 / g.baud
        for r in t["rows"]:
            assert r["seeds"] == 1
            assert r["ci"]["p_detect"]["values"] == [r["p_detect"]]
            assert r["p_detect"] == pytest.approx(r["detections"] / r["frames_in_fov"])
            if r["latency_mean_s"] is not None:
                assert floor <= r["latency_mean_s"] <= floor + r["window_ms"] / 1000


def test_coverage_at_windows_matches_an_independent_coverage_run(quick):
    from sim.scan.coverage import voxel_coverage, voxel_grid
    from sim.scan.model import ScanModel
    from sim.scan.presets import MID40
    from sim.study.common import QUICK

    _, res, _ = quick
    c = res["axes"]["sensing"]["coverage"]["mid40"]
    assert np.all(np.diff(c["coverage"]) >= 0)
    grid = voxel_grid(MID40, reference_rays=QUICK.coverage_rays)
    for w, cov in c["at_windows"].items():
        curve = voxel_coverage(ScanModel(MID40), int(w) / 1000, grid)
        assert cov == pytest.approx(curve.coverage[-1], abs=1e-12)


def test_truth_table_reconstructs_the_head_exactly_and_nominal_does_not(quick):
    """No head ripple in fig12: dead reckoning with the unit's own curve is the head's own motion."""
    _, res, _ = quick
    rows = {r["plan"]: r for r in res["axes"]["calibration"]["rows"]}
    assert rows["truth"]["pointing_rms_deg"] < 1e-6
    assert rows["nominal"]["pointing_rms_deg"] > 0.1
    measured = [r for r in res["axes"]["calibration"]["rows"] if r["plan"] not in ("truth", "nominal")]
    assert measured and all(r["failed"] == 0 and r["cal_virtual_s"] > 0 for r in measured)


def test_pareto_tables_in_the_report_are_consistent_with_the_points(quick):
    from sim.study.pareto import cheapest_for, pareto_front

    _, res, _ = quick
    for axis, groups in res["pareto"].items():
        for g in groups.values():
            assert [p["label"] for p in g["front"]] == [p["label"] for p in pareto_front(g["points"])]
            for c in g["cheapest"]:
                err = 1 - c["target"] if axis == "sensing_detect" else c["target"]
                best = cheapest_for(g["points"], err)
                assert c["label"] == (best["label"] if best else None)
                if best is not None:     # recommended only if its whole error interval meets the target
                    assert c["error_hi"] <= err + 1e-15


def test_levers_that_must_not_change_the_loop_do_not(quick):
    """Recording a run, or carrying an IMU whose gyro is not used, must leave every tracking metric
    of the same seed as it was; the reference's paired change is zero by construction."""
    _, res, _ = quick
    lv = res["axes"]["levers"]
    rows = {r["lever"]: r for r in lv["rows"]}
    assert set(rows) == set(__import__("sim.study.levers", fromlist=["LEVERS"]).LEVERS)
    for lever in ("recording on", "IMU, commands", lv["reference"]):
        for k in ("error_rms_all_deg", "recon_rms_m"):
            d = rows[lever]["delta"][k]
            assert d["values"] == [0.0] * len(lv["seeds"]), (lever, k, d)
    # the recording's own work costs CPU (written and closed inside the timed block)
    assert all(v > 1.0 for v in rows["recording on"]["cost_ratio"]["values"])
