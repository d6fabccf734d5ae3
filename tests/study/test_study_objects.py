"""The study's sky axis (section 8 of docs/accuracy-vs-time.md, issue 28): the multi-object tracker's
frame against the objects and the points in the field, with what it tracks; and the route that
regenerates only that section.  Times are not asserted (benchmarks print them); the cases, the
pairing and the route are."""

import math

import numpy as np
import pytest

from foveatrack.cli import main
from one_axis import run_one_axis
from sim.study import sky_objects as so
from sim.study.common import QUICK


def test_the_cases_change_what_they_say_and_nothing_else():
    base = so.sky_scene("drone-and-flock", 2.0, 7)
    assert base.seed == 7 and base.duration_s == 2.0
    birds = [o for o in base.others if o.cls == "bird"]
    assert len(birds) == 20
    assert not [o for o in so.sky_scene("drone-and-flock", 2.0, 7, birds=0).others if o.cls == "bird"]
    assert len([o for o in so.sky_scene("drone-and-flock", 2.0, 7, birds=80).others if o.cls == "bird"]) == 80
    swarm = so.sky_scene("swarm-of-five", 2.0, 7)
    both = so.sky_scene("swarm-of-five", 2.0, 7, flock_of="drone-and-flock")
    assert len(both.targets) == len(swarm.targets) == 5
    assert len([o for o in both.others if o.cls == "bird"]) == 20 + len([o for o in swarm.others if o.cls == "bird"])
    assert so.sky_scene("swarm-of-five", 2.0, 7, preset="horizon").optics.name == "horizon"
    # each seed its own world: the flock is drawn from the seed (the builder once set only the built
    # scene's seed field, and every seed flew one flock)
    t = np.array([1.0])
    first_bird = [o for o in so.sky_scene("drone-and-flock", 2.0, 8).others if o.cls == "bird"][0]
    assert not np.allclose(birds[0].trajectory.position(t), first_bird.trajectory.position(t))
    assert np.array_equal(birds[0].trajectory.position(t),
                          [o for o in so.sky_scene("drone-and-flock", 2.0, 7).others if o.cls == "bird"][0]
                          .trajectory.position(t))
    assert swarm.optics.name == "mid40"
    # every case on the same paired seeds of its scene
    ts = so.tasks(QUICK)
    assert {t.case for t in ts} == {c[0] for c in so.CASES}
    assert all(len([t for t in ts if t.case == c[0]]) == QUICK.seeds for c in so.CASES)


def test_collect_gives_each_case_its_intervals_and_real_time_factor():
    res = []
    for s, ms in ((1, 2.0), (2, 4.0)):
        r = {k: 1.0 for k in so.METRICS}
        r.update(ms_per_frame=ms, period_s=0.1)
        res.append((so.SkyObjectsTask(so.CASES[0][0], s, 2.0), r))
    out = so.collect(res)
    (row,) = out["rows"]
    assert row["case"] == so.CASES[0][0] and row["seeds"] == [1, 2] and out["duration_s"] == 2.0
    assert row["ci"]["ms_per_frame"]["mean"] == pytest.approx(3.0)
    assert row["x_real_time"] == pytest.approx(100.0 / 3.0)


def test_objects_only_route_updates_its_section_and_nothing_else(tmp_path):
    ob, text = run_one_axis(tmp_path, "objects", "--quick", "--workers", "2")
    rows = {r["case"]: r for r in ob["rows"]}
    assert list(rows) == [c[0] for c in so.CASES]
    assert [rows[f"drone-and-flock, {n} birds"]["ci"]["objects"]["mean"] for n in (0, 5, 20, 80)] == [1, 6, 21, 81]
    mid = rows["swarm-of-five"]["ci"]["points_per_frame"]["mean"]
    hor = rows["swarm-of-five, Horizon (240 k points/s)"]["ci"]["points_per_frame"]["mean"]
    assert hor > 2.0 * mid                      # the Horizon's 240 k points/s against the Mid-40's 100 k
    for r in ob["rows"]:
        assert all(math.isfinite(r["ci"][k]["mean"]) for k in so.METRICS), r["case"]
        assert 0.0 <= r["ci"]["confirmed_within_2s_share"]["mean"] <= 1.0
    assert ob["run"]["command"].startswith("foveatrack study accuracy-vs-time --axis objects --quick")
    assert "## 8. The sky" in text and "| swarm-of-five + the 20-bird flock |" in text


def test_objects_route_user_errors(tmp_path, capsys):
    assert main(["study", "accuracy-vs-time", "--axis", "objects", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "--axis objects" in err and "run the whole study" in err
    assert main(["study", "accuracy-vs-time", "--axis", "objects", "--effects", "weather", "--out", str(tmp_path)]) == 2
    assert "--axis effects" in capsys.readouterr().err
