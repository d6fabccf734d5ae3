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


def _run(argv, capsys):
    code = main(argv)
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return code, err


def test_output_paths_are_checked_before_the_work(tmp_path, capsys):
    missing = tmp_path / "no-such-dir"
    # replay: before, the export failed with a FileNotFoundError traceback after the whole replay;
    # the recording here does not even exist, so the export path is what was checked first
    code, err = _run(["replay", str(tmp_path / "nothing.mcap"), "--export-points", str(missing / "p.csv")], capsys)
    assert code == 2 and "--export-points" in err and "does not exist" in err
    code, err = _run(["replay", str(tmp_path / "nothing.mcap"), "--export-trajectory", str(tmp_path / "t.txt")], capsys)
    assert code == 2 and "--export-trajectory" in err and ".csv or .npz" in err
    # calibrate: before, minutes of calibration ran and then table.save raised FileNotFoundError
    code, err = _run(["calibrate", "--scene", ROOM, "--out", str(missing / "t.json")], capsys)
    assert code == 2 and "--out" in err and "does not exist" in err
    code, err = _run(["calibrate", "--scene", ROOM, "--out", str(tmp_path)], capsys)
    assert code == 2 and "is a directory" in err
    # lidar plots: before, matplotlib's savefig raised FileNotFoundError after the analysis
    code, err = _run(["lidar", "info", "mid40", "--plot", str(missing / "i.png")], capsys)
    assert code == 2 and "--plot" in err and "does not exist" in err
    assert not missing.exists()


def test_an_os_error_in_any_command_is_one_line_naming_the_file(monkeypatch, capsys):
    from foveatrack.cli import lidar_cmd

    def full_disk(args):
        raise OSError(28, "No space left on device", "/data/out.png")

    monkeypatch.setattr(lidar_cmd, "cmd_info", full_disk)
    code, err = _run(["lidar", "info", "mid40"], capsys)
    assert code == 2
    assert err.strip() == "foveatrack: error: /data/out.png: No space left on device"


def test_pattern_duration_beyond_memory_is_refused(capsys):
    # before: numpy's _ArrayMemoryError ("Unable to allocate 728. TiB") traceback
    code, err = _run(["lidar", "pattern", "mid40", "--duration", "1e9"], capsys)
    assert code == 2 and "--duration 1e+09" in err and "at most 20000000" in err
