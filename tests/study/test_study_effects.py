"""The study's effects axis (issue 31): every effect a scene can list, added alone to fig12, its cost
per frame and its change of the tracking error against fig12 as shipped, paired by seed; and the
route that regenerates only that section of the report."""

import shutil
from pathlib import Path

import pytest

from foveatrack.cli import main
from sim.study import effect_costs as ec
from one_axis import run_one_axis
from sim.study.common import QUICK

DOCS = Path(__file__).resolve().parents[2] / "docs"


def test_the_axis_measures_every_listable_effect_but_the_reference_s_own(monkeypatch):
    from sim import scene as sc

    fig12 = set(ec._fig12_data()["scene"]["effects"])
    assert set(ec.measured_effects()) == set(sc.EFFECT_DEFAULTS) - fig12
    assert set(ec.excluded()) == fig12 and all(ec.excluded().values())
    # an effect another branch adds to the table is measured without a change here
    monkeypatch.setitem(sc.EFFECT_DEFAULTS, "head_backlash", {})
    assert "head_backlash" in ec.measured_effects()
    ts = ec.tasks(QUICK, ["weather"])
    assert {(t.effect, t.seed) for t in ts} == {(e, s) for e in (None, "weather") for s in (12, 1012)}
    scene = ec.effect_scene("weather", 1.0, 5)
    assert scene.has("weather") and scene.seed == 5 and scene.duration_s == 1.0
    assert ec.effect_scene(None, 1.0, 5).effects == frozenset(fig12)


def test_collect_pairs_by_seed():
    ts = [ec.EffectTask(e, s, 2.0) for s in (1, 2, 3) for e in (None, "weather")]
    res = []
    for t in ts:
        base = {1: 1.0, 2: 2.0, 3: 4.0}[t.seed]
        k = 1.5 if t.effect else 1.0
        res.append((t, {"error_rms_acq_deg": base + (0.1 if t.effect else 0.0), "error_rms_all_deg": base,
                        "acquisition_s": 1.0, "cpu_per_virtual_s": k * base, "ms_per_frame": k * base}))
    out = ec.collect(res)
    ref, w = out["rows"]
    assert ref["effect"] == ec.REFERENCE and w["effect"] == "weather" and out["seeds"] == [1, 2, 3]
    assert w["cost_ratio"]["mean"] == pytest.approx(1.5) and w["cost_ratio"]["half"] == pytest.approx(0.0, abs=1e-12)
    assert w["delta"]["error_rms_acq_deg"]["mean"] == pytest.approx(0.1)
    assert ref["delta"]["error_rms_acq_deg"]["mean"] == 0.0 and ref["cost_ratio"]["mean"] == 1.0
    # a later run of some effects keeps the others' rows
    other = ec.collect([(ec.EffectTask(e, s, 2.0), r) for (t, r) in res for e, s in [(t.effect and "incidence", t.seed)]])
    merged = ec.merge(out, other)
    assert [r["effect"] for r in merged["rows"]] == [ec.REFERENCE, "weather", "incidence"]
    # ... measured on the same CPU; another's milliseconds are not mixed into this run's table
    out["run"] = {"cpu": "AMD EPYC"}
    assert [r["effect"] for r in ec.merge(out, other, "AMD EPYC")["rows"]] == [ec.REFERENCE, "weather", "incidence"]
    assert [r["effect"] for r in ec.merge(out, other, "Intel Xeon")["rows"]] == [ec.REFERENCE, "incidence"]


def test_effects_only_route_updates_its_section_and_nothing_else(tmp_path):
    ef, text = run_one_axis(tmp_path, "effects", "--effects", "weather", "--quick", "--workers", "1")
    assert [r["effect"] for r in ef["rows"]] == [ec.REFERENCE, "weather"] and ef["seeds"] == [12, 1012]
    assert ef["run"]["command"].startswith("foveatrack study accuracy-vs-time --axis effects --effects weather")
    assert "## 7. The effects" in text and "| weather |" in text


def test_effects_route_user_errors(tmp_path, capsys):
    assert main(["study", "accuracy-vs-time", "--axis", "effects", "--out", str(tmp_path)]) == 2
    assert "run the whole study" in capsys.readouterr().err
    assert main(["study", "accuracy-vs-time", "--effects", "weather", "--out", str(tmp_path)]) == 2
    assert "--axis effects" in capsys.readouterr().err
    shutil.copy(DOCS / "accuracy-vs-time.json", tmp_path / "accuracy-vs-time.json")
    assert main(["study", "accuracy-vs-time", "--axis", "effects", "--effects", "moonlight,range_noise",
                 "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "moonlight" in err and "range_noise" in err and "weather" in err


def test_an_effect_that_needs_another_is_measured_with_it():
    scene = ec.effect_scene("mixed_pixels", 1.0, 5)
    assert scene.has("mixed_pixels") and scene.has("beam_footprint")
    assert ec.label("mixed_pixels") == "mixed_pixels + beam_footprint"
    assert ec.label("range_noise_model") == "range_noise_model"        # fig12 lists range_noise
    assert ec.effect_scene("range_noise_model", 1.0, 5).has("range_noise")
