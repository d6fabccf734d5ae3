"""What bothered new users in their first hour (issue 30's list), each checked through the CLI as they
ran it: an error that names what was wrong, never a line that contradicts itself or a flag that is
silently ignored."""

import os
from pathlib import Path

from foveatrack.cli import main

ROOT = Path(__file__).resolve().parents[1]
SCENE = str(ROOT / "scenes" / "fig12-tracking.toml")


def _run(argv, capsys):
    code = main(argv)
    out = capsys.readouterr()
    assert "Traceback" not in out.err
    return code, out.out, out.err


def test_lidar_info_with_the_paraxial_model_names_the_exact_one_second(capsys):
    # before: "paraxial model of the same optics: 65.84 x 20.97 deg (error -15.86 ...)" under a first
    # line that was the paraxial model already
    code, out, _ = _run(["lidar", "info", "horizon", "--model", "paraxial"], capsys)
    first, second = out.splitlines()[:2]
    assert code == 0
    assert "65.84 x 20.97 deg (paraxial model)" in first
    assert "exact model of the same optics: 81.70 x 25.10 deg" in second
    code, out, _ = _run(["lidar", "info", "horizon"], capsys)
    assert "paraxial model of the same optics: 65.84 x 20.97 deg" in out.splitlines()[1]


def test_gimbal_serve_link_into_a_missing_directory_names_it(tmp_path, capsys):
    # before: "[Errno 2] No such file or directory: '/dev/pts/0' -> '.../head.tmp15475'"
    link = tmp_path / "no-such-dir" / "head"
    code, _, err = _run(["gimbal", "serve", "--link", str(link)], capsys)
    assert code == 2
    assert f"the directory {link.parent} does not exist" in err and ".tmp" not in err


def test_gimbal_serve_link_never_replaces_a_regular_file(tmp_path, capsys):
    kept = tmp_path / "notes.txt"
    kept.write_text("mine")
    code, _, err = _run(["gimbal", "serve", "--link", str(kept)], capsys)
    assert code == 2 and "not a symlink" in err
    assert kept.read_text() == "mine" and not kept.is_symlink()


def test_simulate_speed_without_live_is_refused_not_ignored(capsys):
    code, _, err = _run(["simulate", SCENE, "--speed", "3", "--duration", "0.2"], capsys)
    assert code == 2 and "--speed 3 paces the live view: add --live" in err


def _daemon_config(tmp_path, recording_path: str, make_dirs: bool) -> Path:
    text = (ROOT / "examples" / "daemon-virtual.toml").read_text()
    text = text.replace('path = "../out/runs/daemon-{time}.mcap"', f'path = "{recording_path}"')
    text = text.replace("make_dirs = true", f"make_dirs = {'true' if make_dirs else 'false'}")
    assert recording_path in text
    cfg = tmp_path / "daemon.toml"
    cfg.write_text(text)
    for table in (ROOT / "examples").glob("*.json"):    # the speed table it names, beside it
        (tmp_path / table.name).write_text(table.read_text())
    return cfg


def test_daemon_check_refuses_a_recording_directory_that_is_missing(tmp_path, capsys):
    # before: --check passed, and the run then failed at once; the check comes before the devices
    # are opened, so no head or lidar is needed to see it
    cfg = _daemon_config(tmp_path, str(tmp_path / "no-such-dir" / "run-{time}.mcap"), make_dirs=False)
    code, _, err = _run(["daemon", "--config", str(cfg), "--check"], capsys)
    assert code == 2
    assert "[recording] path: the directory" in err and "no-such-dir" in err and "does not exist" in err


def test_daemon_check_refuses_a_recording_directory_it_cannot_write(tmp_path, capsys):
    if os.geteuid() == 0:
        # root writes anywhere; a file where the directory should be is unwritable for root too
        (tmp_path / "blocked").write_text("")
        where = tmp_path / "blocked" / "runs" / "run-{time}.mcap"
    else:
        (tmp_path / "ro").mkdir(mode=0o500)
        where = tmp_path / "ro" / "run-{time}.mcap"
    cfg = _daemon_config(tmp_path, str(where), make_dirs=True)
    code, _, err = _run(["daemon", "--config", str(cfg), "--check"], capsys)
    assert code == 2 and "is not a directory this user can write in" in err


def test_simulate_and_replay_name_the_same_plots_alike(tmp_path, capsys):
    # before: simulate wrote error.png, trajectory.png, ... and replay fig14b_error_vs_time.png,
    # fig14c_trajectory.png, ... for the same figures
    run = tmp_path / "run"
    code, _, _ = _run(["simulate", SCENE, "--duration", "1", "--out", str(run), "--plot", "--no-progress",
                       "--one-thread"], capsys)
    assert code == 0
    code, _, _ = _run(["replay", str(run / "run.mcap"), "--plot", str(tmp_path / "replay")], capsys)
    assert code == 0
    sim = {p.name for p in run.glob("*.png")}
    assert sim == {p.name for p in (tmp_path / "replay").glob("*.png")}
    assert {"error.png", "trajectory.png", "points_on_target.png", "head.png"} <= sim


def test_calibrate_imu_on_a_scene_without_imu_says_so_before_any_progress_bar(capsys):
    # before: "\rsimulating scans:   0%| ... foveatrack: error: ... no [imu] table" on one line
    code, _, err = _run(["calibrate-imu", SCENE], capsys)
    assert code == 2
    assert err.startswith("foveatrack: error:") and "no [imu] table" in err
    assert "\r" not in err and "simulating" not in err


def test_every_option_of_every_command_says_what_it_does():
    # before: --no-progress on seven commands, gimbal serve --pan0-deg, lidar density --bins, ... had none
    import argparse

    from foveatrack.cli import build_parser

    missing = []

    def walk(parser, path):
        for a in parser._actions:
            if isinstance(a, argparse._SubParsersAction):
                for name, sub in a.choices.items():
                    walk(sub, path + [name])
            elif not isinstance(a, argparse._HelpAction) and not a.help:
                missing.append(f"{' '.join(path)} {'/'.join(a.option_strings) or a.dest}")

    walk(build_parser(), ["foveatrack"])
    assert missing == []


FIG12_V2 = str(ROOT / "tests" / "recording" / "fixtures" / "fig12-v2.mcap")


def test_export_imu_of_a_run_without_imu_writes_nothing_else_first(tmp_path, capsys):
    # before: the points were written, then the IMU export failed
    code, _, err = _run(["export", FIG12_V2, "--csv", str(tmp_path / "p.csv"), "--imu", str(tmp_path / "i.csv")],
                        capsys)
    assert code == 2 and "holds no IMU samples" in err
    assert list(tmp_path.iterdir()) == []


def test_the_trajectory_csv_has_no_column_that_is_always_blank(tmp_path, capsys):
    # before: xyz_m and world_xyz_m came beside xyz_m[0..2] and world_xyz_m[0..2], blank in every row
    import csv

    out = tmp_path / "t.csv"
    code, _, _ = _run(["export", FIG12_V2, "--trajectory", str(out)], capsys)
    assert code == 0
    rows = list(csv.reader(out.open()))
    header, body = rows[0], rows[1:]
    assert "xyz_m[0]" in header and "xyz_m" not in header and "world_xyz_m" not in header
    blank = [h for i, h in enumerate(header) if all(r[i] == "" for r in body)]
    assert blank == [], blank
