"""What a user already has is not replaced unasked (a user session found each of these): simulate's
--out holding an earlier run's recording, an export over an existing file, two outputs of one command
with one name, a track --csv named after one of its own input scans.  --overwrite replaces what
exists, and never an input."""

import hashlib
from pathlib import Path

import numpy as np
import pytest

from foveatrack.cli import main

ROOT = Path(__file__).resolve().parents[1]
FIG12 = str(ROOT / "scenes" / "fig12-tracking.toml")


def _run(argv, capsys):
    code = main(argv)
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return code, err


def _md5(p) -> str:
    return hashlib.md5(Path(p).read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    out = tmp_path_factory.mktemp("kept") / "run"
    assert main(["simulate", FIG12, "--duration", "1", "--out", str(out), "--no-progress", "--one-thread"]) == 0
    return out


def test_simulate_does_not_replace_an_earlier_runs_recording_unasked(recording, capsys):
    before = _md5(recording / "run.mcap")
    code, err = _run(["simulate", FIG12, "--duration", "0.5", "--out", str(recording), "--no-progress"], capsys)
    assert code == 2 and "--out" in err and "earlier run" in err and "--overwrite" in err
    assert _md5(recording / "run.mcap") == before
    other = recording.parent / "again"
    assert main(["simulate", FIG12, "--duration", "0.5", "--out", str(other), "--no-progress", "--one-thread"]) == 0
    assert main(["simulate", FIG12, "--duration", "1", "--out", str(other), "--no-progress", "--one-thread",
                 "--overwrite"]) == 0
    assert _md5(other / "run.mcap") == before          # the same 1 s run, written anew


def test_demo_replaces_its_own_directory_only(recording, capsys):
    # before: demo --out replaced any directory's recording (a user's audit: a simulate run's)
    before = _md5(recording / "run.mcap")
    code, err = _run(["demo", "--out", str(recording), "--no-progress"], capsys)
    assert code == 2 and "earlier run" in err and "--overwrite" in err
    assert _md5(recording / "run.mcap") == before
    # its own default directory is replaced without asking (the quick start run again)
    from foveatrack.cli.demo_cmd import DEFAULT_OUT, replaces

    assert replaces(DEFAULT_OUT, False) and replaces("out/demo/", False) and not replaces(recording, False)
    assert replaces(recording, True)


def test_export_keeps_existing_files_and_one_name_per_output(recording, tmp_path, capsys):
    rec = str(recording / "run.mcap")
    mine = tmp_path / "mine.lvx"
    mine.write_bytes(b"livox_tech and the user's own data")
    code, err = _run(["export", rec, "--lvx", str(mine)], capsys)
    assert code == 2 and "--lvx" in err and "exists" in err and mine.read_bytes().startswith(b"livox_tech and")
    code, err = _run(["export", rec, "--csv", str(tmp_path / "same.csv"), "--trajectory", str(tmp_path / "same.csv")],
                     capsys)
    assert code == 2 and "writes the same file" in err and not (tmp_path / "same.csv").exists()
    assert main(["export", rec, "--csv", str(tmp_path / "p.csv")]) == 0
    code, err = _run(["export", rec, "--csv", str(tmp_path / "p.csv")], capsys)
    assert code == 2 and "--overwrite" in err
    assert main(["export", rec, "--csv", str(tmp_path / "p.csv"), "--overwrite"]) == 0
    # the recording itself is never an output, --overwrite or not (an .mcap is not a csv name anyway:
    # a trajectory .npz named like the recording's copy shows the input rule)
    copy = tmp_path / "run.npz"
    copy.write_bytes(Path(rec).read_bytes())
    code, err = _run(["export", str(copy), "--trajectory", str(copy), "--overwrite"], capsys)
    assert code == 2 and "reads" in err and copy.read_bytes() == Path(rec).read_bytes()
    code, err = _run(["replay", rec, "--export-points", str(tmp_path / "p.csv")], capsys)
    assert code == 2 and "--export-points" in err and "--overwrite" in err


def test_track_never_writes_over_a_scan_it_reads(tmp_path, capsys):
    from pypcd4 import PointCloud

    folder = tmp_path / "scans"
    folder.mkdir()
    rng = np.random.default_rng(0)
    for k in range(3):
        xyz = np.vstack([rng.uniform(-1, 1, (40, 3)) + [20, 0, 2], rng.uniform(-5, 5, (40, 3)) + [40, 0, 0]])
        PointCloud.from_points(xyz, ("x", "y", "z"), (np.float64,) * 3).save(folder / f"1706255621.{k}00000.pcd")
    scan = folder / "1706255621.000000.pcd"
    before = _md5(scan)
    code, err = _run(["track", str(folder), "--csv", str(scan)], capsys)
    assert code == 2 and "--csv" in err and ".csv" in err and _md5(scan) == before
    named = folder / "1706255621.000000.csv"
    named.write_text("the user's notes\n")
    code, err = _run(["track", str(folder), "--csv", str(named)], capsys)
    assert code == 2 and "reads" in err and named.read_text() == "the user's notes\n"


def test_points_an_lvx_export_leaves_out_are_a_warning_of_their_own(tmp_path, capsys):
    # A track --record recording of PCD scans (no per-point time: a scan's points share one instant)
    # exported to .lvx lost 94 % of its points, said only as a clause of the success line.
    from pypcd4 import PointCloud

    folder = tmp_path / "scans"
    folder.mkdir()
    rng = np.random.default_rng(1)
    for k in range(3):
        xyz = rng.uniform(-1, 1, (30, 3)) + [20, 0, 2]
        PointCloud.from_points(xyz, ("x", "y", "z"), (np.float64,) * 3).save(folder / f"1706255621.{k}00000.pcd")
    rec = tmp_path / "tr.mcap"
    assert main(["track", str(folder), "--box", "10", "-5", "-3", "30", "5", "6", "--record", str(rec)]) == 0
    capsys.readouterr()
    assert main(["export", str(rec), "--lvx", str(tmp_path / "t.lvx")]) == 0
    err = capsys.readouterr().err
    assert "WARNING" in err and "were left out" in err and "share a scan slot" in err, err
    # the recording names no lidar: the file's device type is a guess, and said to be one (an audit found
    # an Avia's recording written as a Mid-40 without a word)
    assert "the recording names no lidar, so the file calls it a mid40 (device type 1)" in err, err
    assert "--device names the real one" in err
    assert main(["export", str(rec), "--lvx", str(tmp_path / "a.lvx"), "--device", "avia"]) == 0
    assert "names no lidar" not in capsys.readouterr().err


@pytest.mark.parametrize("argv", [["calibrate", "--scene", str(ROOT / "scenes" / "calibration-room.toml")],
                                  ["calibrate-imu", str(ROOT / "scenes" / "imu-calibration-yard.toml")]])
def test_a_calibration_keeps_a_table_that_exists(argv, tmp_path, capsys):
    # a user's live-measured speed table (the one the daemon config names) was replaced by a simulated
    # calibration's, without a word; refused before the calibration runs
    table = tmp_path / "precious.json"
    table.write_text('{"the user": "measured on the live head"}')
    code, err = _run([*argv, "--out", str(table)], capsys)
    assert code == 2 and "--out" in err and "exists" in err and "--overwrite" in err, err
    assert table.read_text() == '{"the user": "measured on the live head"}'
