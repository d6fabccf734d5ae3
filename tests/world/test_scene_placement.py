"""A scene's drones and birds against its ground and the head (:mod:`sim.scene_placement`): a drone
under the ground or at the head ran and was never seen, and nothing said why."""

from pathlib import Path

import pytest

from foveatrack.cli import main
from foveatrack.errors import UserError
from sim.scene import load_scene

SCENES = Path(__file__).resolve().parents[2] / "scenes"


def _scene(tmp_path, start_m, velocity_m_s=(0.0, -0.5, 0.0), extra=""):
    """A 3 s scene: the head 1.5 m above the ground, one drone flying straight."""
    path = tmp_path / "s.toml"
    path.write_text(f"""[scene]
duration_s = 3.0
[[target]]
[target.trajectory]
type = "straight"
start_m = {list(start_m)}
velocity_m_s = {list(velocity_m_s)}
[[background]]
type = "ground"
height_m = 1.5
{extra}""")
    return path


def test_a_drone_under_the_ground_all_run_is_an_error_naming_it_when_and_where(tmp_path):
    path = _scene(tmp_path, (12.0, 2.4, -2.0))
    with pytest.raises(UserError) as exc:
        load_scene(path)
    msg = str(exc.value)
    for words in ("s.toml [[target]] #1 (drone-1)", "below the ground for the whole run", "t = 0 s",
                  "[12, 2.4, -2] m", "0.50 m below the ground plane (1.5 m below the head)", "never see it"):
        assert words in msg, msg


def test_a_drone_at_the_head_all_run_is_an_error(tmp_path):
    with pytest.raises(UserError) as exc:
        load_scene(_scene(tmp_path, (0.3, 0.2, 0.1), (0.0, 0.0, 0.0)))
    msg = str(exc.value)
    assert "[[target]] #1 (drone-1) is inside the lidar's blind zone for the whole run" in msg, msg
    assert "[0.3, 0.2, 0.1] m, 0.37 m from the head's rotation centre (min_range_m 1 m)" in msg, msg


def test_a_drone_that_starts_under_the_ground_is_a_warning_at_its_start(tmp_path, capsys):
    path = _scene(tmp_path, (12.0, 2.4, -1.7), (0.0, -0.5, 1.0))
    (w,) = load_scene(path).warnings()
    assert "s.toml [[target]] #1 (drone-1) is below the ground, first at t = 0 s at [12, 2.4, -1.7] m" in w, w
    # the CLI that flies it says so on stderr, and runs
    assert main(["simulate", str(path), "--duration", "0.3", "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert "foveatrack simulate: WARNING: " + w in err, err


def test_a_drone_that_dives_into_the_ground_is_named_with_the_instant(tmp_path):
    (w,) = load_scene(_scene(tmp_path, (12.0, 2.4, 0.9), (0.0, -0.5, -1.0))).warnings()
    assert "is below the ground, first at t = 2.5 s at [12, 1.15, -1.6] m, 0.10 m below" in w, w


def test_a_path_that_ends_on_the_ground_is_not_under_it(tmp_path):
    # at t = 3 s its centre is at 0.9 - 0.8 * 3.0 = -1.5000000000000004 m: on the ground, to the rounding
    assert load_scene(_scene(tmp_path, (12.0, 2.4, 0.9), (0.0, 0.0, -0.8))).warnings() == []


def test_a_flock_under_the_ground_is_a_warning_naming_the_flock_and_a_bird(tmp_path):
    path = _scene(tmp_path, (12.0, 2.4, 0.9), extra="""[[bird]]
id = "pigeons"
count = 5
[bird.trajectory]
type = "circle"
centre_m = [40.0, 0.0, -4.0]
radius_m = 12.0
speed_m_s = 8.0
""")
    (w,) = load_scene(path).warnings()        # one line for the flock; birds are clutter: no error
    assert w.startswith(f"{path} [[bird]] pigeons (its bird pigeons/") and "below the ground" in w, w


def test_no_shipped_scene_has_a_drone_or_bird_under_the_ground_or_at_the_head():
    scenes = sorted(SCENES.glob("*.toml"))
    assert len(scenes) > 10
    for p in scenes:
        assert load_scene(p).warnings() == [], p


def test_a_sky_warm_up_as_long_as_the_run_is_a_warning():
    # before: accepted silently, and the run tracked nothing (a user-level audit, warmup_s = 100 in
    # the 12 s crossing)
    from dataclasses import replace
    from pathlib import Path

    scene = load_scene(Path(__file__).resolve().parents[2] / "scenes" / "two-drones-crossing.toml")
    assert scene.warnings() == []
    table = dict(scene.tracker_table, sky=dict(scene.tracker_table["sky"], warmup_s=12))
    (w,) = replace(scene, tracker_table=table).warnings()
    assert "[tracker.sky] warmup_s 12 is not shorter than the run (12 s)" in w and "nothing is tracked" in w
