"""Inputs a user gets wrong reach the CLI as one clear line naming the input and what is allowed,
never as a traceback (found by a review that fed the commands wrong values)."""

import pytest

from foveatrack.cli import main

SCENE = "scenes/fig12-tracking.toml"
ROOM = "scenes/calibration-room.toml"


@pytest.mark.parametrize("argv", [
    ["gimbal", "serve", "--unit-seed", "-1"],
    ["gimbal", "curves", "--unit-seeds", "0", "-3", "--plot", "x.png"],
    ["calibrate", "--scene", ROOM, "--unit-seed", "-1"],
    ["calibrate", "--scene", ROOM, "--seed", "-4"],
    ["lidar", "pattern", "mid40", "--noise", "0.01", "--seed", "-2"],
    ["lidar", "coverage-map", "prototype", "--grid", "2", "--seed", "-2"],
    ["lidar", "serve", SCENE, "--loss-rate", "0.1", "--seed", "-2"],
    ["simulate", SCENE, "--seed", "-1"],
])
def test_negative_seed_is_refused_by_the_parser(argv, capsys):
    # before: numpy's SeedSequence raised "ValueError: expected non-negative integer" mid-run
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "a seed must be an integer >= 0" in err and "Traceback" not in err
