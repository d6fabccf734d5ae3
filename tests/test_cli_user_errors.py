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
])  # (simulate --seed -1 was already a UserError: tests/world/test_loop.py)
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


def _scene_with(tmp_path, old, new):
    from pathlib import Path

    text = Path(SCENE).read_text()
    assert old in text
    path = tmp_path / "scene.toml"
    path.write_text(text.replace(old, new, 1))
    return str(path)


def test_scene_tilt0_beyond_the_heads_stops_is_refused(tmp_path, capsys):
    # before: the closed loop clamped 95 deg to the 60 deg stop and ran from there, silently
    path = _scene_with(tmp_path, "unit_seed = 3", "unit_seed = 3\ntilt0_deg = 95")
    code, err = _run(["simulate", path], capsys)
    assert code == 2
    assert f"{path} [gimbal]: tilt0_deg 95 is beyond the pts-303 head's tilt stops [-30, 60] deg" in err


def test_a_bad_sky_table_is_refused_before_the_output_directory_is_made(tmp_path, capsys):
    # before: the [tracker.sky] tables were checked when the loop was built, after --out was made
    from pathlib import Path

    path = tmp_path / "sky.toml"
    path.write_text(Path(SCENE).read_text() + "\n[tracker.sky]\nconfirm_hitz = 3\n")
    out = tmp_path / "out"
    code, err = _run(["simulate", str(path), "--out", str(out)], capsys)
    assert code == 2 and "confirm_hitz" in err
    assert not out.exists()


def test_space_of_interest_errors_name_the_file_and_table(tmp_path, capsys):
    # before: "box: min_xyz ... must be below max_xyz ..." with no file or table
    path = _scene_with(tmp_path, "max_xyz = [60.0, 60.0, 40.0]", "max_xyz = [0.0, 60.0, 40.0]")
    code, err = _run(["simulate", path], capsys)
    assert code == 2 and f"{path} [tracker].space: box: min_xyz" in err


def test_speed_table_duplicate_byte_names_the_file(tmp_path, capsys):
    import json

    from foveatrack.errors import UserError
    from foveatrack.speed_table import SpeedTable

    data = SpeedTable.nominal().to_dict()
    entries = data["axes"]["pan"]["entries"]
    entries.append(dict(entries[5]))
    path = tmp_path / "table.json"
    path.write_text(json.dumps(data))
    with pytest.raises(UserError) as exc:
        SpeedTable.load(path)
    assert str(exc.value).startswith(f"speed table {path}: axes.pan: speed byte {entries[5]['byte']} is listed twice")


def test_lidar_serve_refuses_a_non_positive_duration(capsys):
    # before: --duration-s -1 served nothing and exited 0
    code, err = _run(["lidar", "serve", SCENE, "--duration-s", "-1"], capsys)
    assert code == 2 and "--duration-s must be > 0" in err


def test_lidar_serve_head_truth_in_a_missing_directory_is_refused(tmp_path, capsys):
    # before: served with the head frozen at the scene's start pose, saying nothing
    truth = tmp_path / "no-such-dir" / "t.jsonl"
    code, err = _run(["lidar", "serve", SCENE, "--head-truth", str(truth), "--duration-s", "0.2"], capsys)
    assert code == 2 and f"--head-truth {truth}" in err and "does not exist" in err


def test_lidar_serve_says_it_waits_for_a_head_truth_file_not_yet_written(tmp_path, capsys):
    truth = tmp_path / "t.jsonl"    # the head serve may start later: not an error, one line
    code, err = _run(["lidar", "serve", SCENE, "--head-truth", str(truth), "--duration-s", "0.2",
                      "--cmd-port", "0", "--broadcast-port", "55999"], capsys)
    assert code == 0
    waiting = [line for line in err.splitlines() if "does not exist yet" in line]
    assert len(waiting) == 1 and f"--head-truth {truth}" in waiting[0] and "waiting for it" in waiting[0]


def test_lidar_serve_head_truth_this_user_may_not_read_is_refused(tmp_path, capsys, monkeypatch):
    """Before: served with the head frozen at the scene's start pose, saying it followed the file
    (head_truth_lines 0 at the end).  Root reads any file: os.access says "not readable" here, as it
    does for a user and another's 0600 truth file."""
    import os

    truth = tmp_path / "t.jsonl"
    truth.write_text('{"t_s": 0.0, "pan_deg": 0.0, "tilt_deg": 0.0}\n')
    truth.chmod(0o600)
    real_access = os.access
    monkeypatch.setattr(os, "access", lambda p, m, *a, **k: False if str(p) == str(truth) and m & os.R_OK
                        else real_access(p, m, *a, **k))
    code, err = _run(["lidar", "serve", SCENE, "--head-truth", str(truth), "--duration-s", "0.2"], capsys)
    assert code == 2 and f"--head-truth {truth}: this user may not read it (Permission denied" in err, err
    assert "mode 600" in err


def test_a_head_truth_that_appears_unreadable_is_said_once(tmp_path, capsys, monkeypatch):
    """A truth file written later by another user (umask 077): said once, not followed in silence."""
    import sim.lidar_server as ls

    truth = tmp_path / "t.jsonl"
    truth.write_text('{"t_s": 0.0, "pan_deg": 0.0, "tilt_deg": 0.0}\n')

    def denied(path, *a, **k):
        raise PermissionError(13, "Permission denied", str(path))

    monkeypatch.setattr(ls, "open", denied, raising=False)
    tail = ls.TruthTail(str(truth), fallback=(1.0, 2.0))
    for _ in range(3):
        tail.poll(0.0)
    err = capsys.readouterr().err
    assert err.count("WARNING") == 1 and f"--head-truth {truth}: cannot read it (Permission denied)" in err
    assert tail.lines == 0


@pytest.mark.parametrize("argv", [["replay"], ["export", "--csv", "{tmp}/out.csv"], ["recover"]])
def test_a_recording_this_user_may_not_read_says_whose_it_is(tmp_path, capsys, monkeypatch, argv):
    """A recording is its owner's alone (0600): a user replaying a service's recording met only
    'rec.mcap: Permission denied'.  Root reads any file: the open raises what it raises for another
    user."""
    import foveatrack.recording.reader as reader_mod
    from foveatrack.recording import RecordingWriter

    rec = tmp_path / "rec.mcap"
    RecordingWriter(rec, {"source": "daemon"}).close()
    real_open = open

    def denied(path, *a, **k):
        if str(path) == str(rec):
            raise PermissionError(13, "Permission denied", str(path))
        return real_open(path, *a, **k)

    monkeypatch.setattr(reader_mod, "open", denied, raising=False)
    argv = [a.format(tmp=tmp_path) for a in argv]
    code, err = _run(argv[:1] + [str(rec)] + argv[1:], capsys)
    assert code == 2 and f"{rec}: this user may not read it (owner " in err and "mode 600" in err, err
    assert "readable by its owner only" in err and not list(tmp_path.glob("out.csv"))


def test_version_names_the_package_and_what_it_runs_on(capsys):
    import foveatrack

    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith(f"foveatrack {foveatrack.__version__} (Python ")
    from foveatrack.environment import DEPENDENCIES, installed_version
    for dist in DEPENDENCIES:   # every pinned dependency, with the version installed
        assert f"{dist} {installed_version(dist)}" in out
    assert "numba target" in out and len(out.strip().splitlines()) == 2


@pytest.mark.parametrize("raised, interrupted", [
    (KeyboardInterrupt(), True),
    # what a Ctrl-C inside a compiled module's initialisation becomes (scipy's pybind11 modules)
    (ImportError("initialization failed"), True),
    (ImportError("No module named 'x'"), False),
])
def test_a_ctrl_c_anywhere_in_a_command_is_one_line_and_exit_code_130(raised, interrupted, monkeypatch, capsys):
    import foveatrack.cli.warmup_cmd as warmup

    def command(args):
        if interrupted and isinstance(raised, ImportError):
            try:
                raise KeyboardInterrupt
            except KeyboardInterrupt as ctrl_c:
                raise raised from ctrl_c
        raise raised

    monkeypatch.setattr(warmup, "cmd_warmup", command)
    if not interrupted:
        with pytest.raises(ImportError):
            main(["warmup"])
        return
    code, err = _run(["warmup"], capsys)
    assert code == 130 and err == "foveatrack: interrupted\n"


@pytest.mark.parametrize("command", [["replay"], ["export", "--csv", "PTS"]])
@pytest.mark.parametrize("content, wrong", [
    (b"\x8f\x11garbage, not a lidar file" * 4, "byte 0, field signature"),
    (b"livox_tech".ljust(16, b"\0") + bytes([1, 1, 0, 0]) + bytes(9), "byte 20, field magic_code: 0x00000000"),
])
def test_a_damaged_lvx_is_named_by_its_lvx_header_not_the_mcap_magic(tmp_path, capsys, command, content, wrong):
    """A garbage file named .lvx was reported as lacking the MCAP magic (replay and export read it as a
    recording); a .lvx whose signature is right but magic is not asked replay for a tracker config."""
    lvx = tmp_path / "scan.lvx"
    lvx.write_bytes(content)
    argv = [a.replace("PTS", str(tmp_path / "p.csv")) for a in command]
    code, err = _run(argv[:1] + [str(lvx)] + argv[1:], capsys)
    assert code != 0 and len(err.strip().splitlines()) == 1, err
    if command[0] == "export" and content.startswith(b"livox_tech"):
        wrong = "is already a Livox .lvx file"    # export reads no .lvx at all: that is what it says
    else:
        assert "is not a readable Livox .lvx v1.1 file" in err
    assert wrong in err and "MCAP" not in err, err
    assert not (tmp_path / "p.csv").exists()


def test_a_turbo_tilt_byte_is_named_as_the_user_gave_it(capsys):
    # "--tilt-bytes turbo" was answered "tilt bytes [255] not allowed": the user wrote no 255
    code, err = _run(["calibrate", "--scene", ROOM, "--tilt-bytes", "turbo"], capsys)
    assert code == 2 and "tilt bytes turbo not allowed" in err and "the tilt has no turbo" in err, err


def test_the_helps_preset_lists_are_the_presets(capsys):
    # coverage-map's help named prototype and mid40 where avia ran too, calibrate-imu's left out four
    # (a user's audit): each list is every preset it takes
    from foveatrack.cli.lidar_cmd import TWO_PRISM_PRESETS
    from sim.scan.presets import PRESETS

    assert list(TWO_PRISM_PRESETS) == [n for n, o in PRESETS.items() if len(o.prisms) == 2]
    with pytest.raises(SystemExit):
        main(["calibrate-imu", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert all(n in out for n in PRESETS), out
