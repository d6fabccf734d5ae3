"""Replay: deterministic re-run of a simulator recording, what a different config changes, cut
recordings, the CLI (JSON, plots, exports), and .lvx files (lidar only, head frozen)."""

import json
import os
from pathlib import Path

import numpy as np
import pytest

from foveatrack.cli import main
from foveatrack.errors import UserError
from foveatrack.livox import protocol as P
from foveatrack.livox.lvx import LvxDevice, write_lvx
from foveatrack.replay import replay, replay_recording
from sim.summary import summarize
from sim.lidar_server import SceneSource
from sim.scene import scene_from_mapping

SCENE = Path(__file__).parent / "scene_track.toml"


@pytest.fixture
def sim_run(sim_recording):
    return sim_recording


@pytest.mark.determinism
def test_simulator_recording_replays_identically(sim_run):
    path, log, scene = sim_run
    res = replay_recording(path)
    c = res.comparison
    assert c["detections_equal"] and c["commands_equal"] and c["commands_compared"] == len(log["t_end_s"])
    assert c["tracker_config_as_recorded"] is True   # the effective configuration the run recorded
    assert c["max_detection_xyz_diff_m"] == 0.0
    assert np.array_equal(res.frames["detected"], log["detected"])
    assert np.array_equal(res.frames["command"], log["command"])
    # the metrics the simulator prints for the run (sim.summary, from its own log): replay reports
    # the same acquisition time and errors, by the same rule (they used to differ: 1.30 vs 1.40 s)
    ref = summarize(scene, log, 1.0)
    got = res.metrics["tracking"]
    for k in ("frames", "frames_with_detection", "acquisition_s", "in_fov_t_s", "acquired_t_s",
              "tracking_error_deg", "reconstruction_error_m", "reconstruction_error_rel"):
        assert got[k] == ref[k], k
    assert got["acquisition_s"] is not None
    # and twice is the same, to the bit
    again = replay_recording(path)
    for k, v in res.frames.items():
        assert np.array_equal(v, again.frames[k], equal_nan=v.dtype.kind == "f"), k


def test_other_config_shows_what_changes(sim_run, tmp_path):
    path, log, _ = sim_run
    cfg = tmp_path / "tight.toml"
    cfg.write_text(SCENE.read_text().replace("deadband_deg = 2.0", "deadband_deg = 0.5").replace(
        "gain_1_s = 2.0", "gain_1_s = 4.0"))
    res = replay(path, str(cfg))
    c = res.comparison
    assert c["frames_command_differs"] > 0 and not c["commands_equal"]
    assert res.config == str(cfg)
    # the detections themselves come from the same points: Algorithm 1 does not depend on the gains
    # (only through the world-frame D, via the reconstructed head pose)
    assert c["detected_replayed"] >= c["detected_recorded"] - 2


def test_cut_recording_replays_its_complete_frames(sim_run, tmp_path):
    path, log, _ = sim_run
    cut = tmp_path / "cut.mcap"
    data = Path(path).read_bytes()
    cut.write_bytes(data[: int(len(data) * 0.6)])
    res = replay_recording(cut)
    n = len(res.frames["t_end_s"])
    assert 5 < n < len(log["t_end_s"])
    assert res.comparison["detections_equal"] and not res.comparison["recording_complete"]
    assert np.array_equal(res.frames["detected"], log["detected"][:n])


def test_replay_of_a_recording_a_writer_or_a_recover_holds_says_so_not_damaged(sim_run, tmp_path, monkeypatch, capsys):
    """replay called the end of a file still being written, or being rewritten by 'foveatrack recover',
    a damaged recording ("file cut short"), where export said it was being written: the reader knows
    who holds the file's lock, and replay says it as export does (what to wait for, not damage)."""
    import foveatrack.atomic_file as af
    from foveatrack.daemon.recover import recover
    from foveatrack.file_lock import hold

    path, _, _ = sim_run
    cut = tmp_path / "cut.mcap"
    data = Path(path).read_bytes()
    cut.write_bytes(data[: int(len(data) * 0.6)])

    def replay_says(*args):
        capsys.readouterr()
        assert main(["replay", str(cut), *args]) == 0
        out = capsys.readouterr()
        return out.err if "--json" in args else out.out

    fd = hold(cut)                  # its writer's lock, as a running simulator or daemon holds it
    try:
        for said in (replay_says(), replay_says("--json")):
            assert "still being written by a running process" in said and "damaged" not in said, said
    finally:
        os.close(fd)
    assert "WARNING: damaged recording" in replay_says()      # let go: its end is damage again

    real, during = af._fsync, []

    def fsync_spy(p, flags):         # the recover's copy is written, not yet renamed over the recording
        if not during and str(p).endswith(".tmp"):
            during.extend([replay_says(), replay_says("--json")])
        return real(p, flags)

    monkeypatch.setattr(af, "_fsync", fsync_spy)
    assert recover(cut).recovered
    for said in during:
        assert "being recovered by a running 'foveatrack recover'" in said and "damaged" not in said, said
        assert "still being written" not in said, said

def test_a_held_recording_damaged_before_its_end_is_said_damaged_too(sim_run, tmp_path, capsys):
    """A held file's cut-short end is not damage, but a stretch skipped before it is: replay said only
    "still being written" of a file with a damaged chunk in its middle (export too), and the frames
    lost there went unsaid."""
    from foveatrack.file_lock import hold
    from foveatrack.recording import RecordingReader

    path, _, _ = sim_run
    whole = Path(path).read_bytes()
    data = bytearray(whole[: int(len(whole) * 0.6)])
    mid = len(data) // 3
    data[mid:mid + 4096] = b"\xff" * 4096            # a damaged stretch well before the end
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(bytes(data))
    fd = hold(cut)                                     # a running writer's lock
    try:
        capsys.readouterr()
        assert main(["replay", str(cut)]) == 0
        said = capsys.readouterr().out
        reader = RecordingReader(cut)
        for _ in reader.messages():
            pass
        warning = reader.warning()
    finally:
        os.close(fd)
    for text in (said, warning):
        assert "still being written by a running process" in text, text
        assert "WARNING: damaged recording" in text and "skipped bytes" in text, text
        assert "file cut short" not in text, text      # the end is the writer's next bytes


def test_cli_json_plots_exports(sim_run, tmp_path, capsys):
    path, log, _ = sim_run
    pts, trj, plots = tmp_path / "p.npz", tmp_path / "t.csv", tmp_path / "plots"
    assert main(["replay", str(path), "--json", "--export-points", str(pts), "--export-trajectory", str(trj),
                 "--plot", str(plots)]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["comparison"]["detections_equal"] and s["frames"] == len(log["t_end_s"])
    assert s["metrics"]["tracking"]["tracking_error_deg"]["rms"] is not None
    z = np.load(pts)
    assert z["x_m"].size == log["points"].sum()
    rows = trj.read_text().splitlines()
    assert len(rows) == len(log["t_end_s"]) + 1 and "true_error_deg" in rows[0]
    # the same names as simulate --plot gives the same figures
    names = ("points_on_target.png", "error.png", "trajectory.png", "head.png")
    assert [Path(o.split(" -> ")[1]).name for o in s["outputs"] if o.startswith("plot")] == list(names)
    for name in names:
        assert (plots / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(["replay", str(tmp_path / "none.mcap")]) == 2


def _box_config(tmp_path) -> str:
    """A bare [tracker] table with a space of interest in the lidar frame (what an .lvx replay needs)."""
    cfg = tmp_path / "box.toml"
    cfg.write_text('[tracker]\n[tracker.space]\nkind = "box"\nmin_xyz = [1.0, -60.0, -5.0]\nmax_xyz = [60.0, 60.0, 40.0]\n')
    return str(cfg)


def test_a_given_tracker_table_without_a_space_of_interest_is_an_error(sim_run, tmp_path):
    path, _, _ = sim_run
    bare = tmp_path / "bare.toml"
    bare.write_text("[tracker]\ndeadband_deg = 0.5\n")
    with pytest.raises(UserError, match=rf"{bare} \[tracker\]: no space of interest .*--tracker-config FILE"):
        replay(path, str(bare))
    assert main(["replay", str(path), "--tracker-config", str(bare)]) == 2


def test_lvx_replay_detects_the_passing_uav(tmp_path, capsys):
    """A frozen-head pass (paper Fig. 13/14a) of a 0.6 m sphere written as a Livox Viewer file: the
    tracker's detections sit on the target (lidar frame = world frame, head frozen at 0; the
    median of points on a sphere's near side is ~ its radius in front of the centre)."""
    scene = scene_from_mapping({
        "scene": {"name": "lvx-pass", "duration_s": 2.0, "seed": 3},
        "lidar": {"preset": "mid40"}, "gimbal": {"frozen": True},
        "target": [{"geometry": "sphere", "radius_m": 0.3,
                    "trajectory": {"type": "straight", "start_m": [10.0, 1.5, 0.0], "velocity_m_s": [0.0, -1.5, 0.0]}}],
    })
    src = SceneSource(scene)
    rate = 100_000.0
    frames = []
    for k in range(40):                     # 2 s in 50 ms lvx frames
        t0, t1 = k * 50_000_000, (k + 1) * 50_000_000
        xyz, refl, t_ns = src(t0, t1)
        slots = np.zeros((5000, 3))
        r = np.zeros(5000, np.uint8)
        i = (t_ns - t0) // 10_000
        slots[i], r[i] = xyz, refl
        frames.append([(0, p) for p in P.encode_data_packets(slots, r, t0, rate, data_type=0)])
    path = tmp_path / "pass.lvx"
    write_lvx(path, frames, [LvxDevice("1PQDH5B00100041", "", 0, 1, False, 0, 0, 0, 0, 0, 0)])
    # an .lvx carries no tracker configuration: without a space of interest replay refuses (it would
    # take every point, the ground too), and names how to give one
    with pytest.raises(UserError, match=r"no space of interest.*--tracker-config FILE whose \[tracker.space\]"):
        replay(path)
    cfg = _box_config(tmp_path)
    res = replay(path, cfg)
    f = res.frames
    assert res.source == "lvx" and len(f["t_end_s"]) == 20
    det = f["detected"]
    assert det.sum() == 20
    truth = scene.targets[0].trajectory.position(f["t_end_s"][det] - 0.05)
    err = np.linalg.norm(f["det_xyz"][det] - truth, axis=1)
    assert err.max() < 0.3                   # within the radius of the centre ...
    assert np.all(np.linalg.norm(f["det_xyz"][det], axis=1) < np.linalg.norm(truth, axis=1))   # ... on the near side
    # head frozen: the reconstruction never moves even though commands were computed
    assert np.all(f["head_pan_deg"] == 0.0) and np.any(f["command"][:, 0] != 0)
    assert main(["replay", str(path), "--tracker-config", cfg, "--json", "--plot", str(tmp_path / "plots")]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["metrics"]["detection"]["frames_with_detection"] == det.sum()
    # no head in a .lvx file: the Fig. 14 plots from the tracker's own estimates, no head-angle plot
    assert sorted(p.name for p in (tmp_path / "plots").iterdir()) == [
        "error.png", "points_on_target.png", "trajectory.png"]


def test_cli_directory_is_named_as_a_directory(tmp_path, capsys):
    """`replay DIR` said "no such recording" though DIR exists: it says it is a directory and names
    the newest .mcap in it (the file the user most likely meant)."""
    import os

    # the newest three, with their sizes: the newest alone was once a run stopped before any frame
    files = [tmp_path / f"run-{k}.mcap" for k in range(4)]
    for k, f in enumerate(files):
        f.write_bytes(b"x" * (k * 300_000))
        os.utime(f, (1_000_000 + k, 1_000_000 + k))
    (tmp_path / "later.txt").write_text("not a recording")   # newer, but not an .mcap
    assert main(["replay", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "is a directory" in err and "no such recording" not in err
    assert f"{files[3]} (0.9 MB), {files[2]} (0.6 MB), {files[1]} (0.3 MB)" in err and str(files[0]) not in err
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["replay", str(empty)]) == 2
    err = capsys.readouterr().err
    assert "is a directory" in err and "no .mcap files" in err


def test_cli_empty_tracker_config_is_refused(sim_run, tmp_path, capsys):
    """An empty --tracker-config file was silently read as all defaults; it is refused, naming the
    file. A bare `[tracker]` (explicitly empty) is refused too: it names no space of interest (issue 25)."""
    path, _, _ = sim_run
    for text in ("", "# to do\n\n"):
        cfg = tmp_path / "empty.toml"
        cfg.write_text(text)
        assert main(["replay", str(path), "--tracker-config", str(cfg)]) == 2
        err = capsys.readouterr().err
        assert f"--tracker-config {cfg}" in err and "empty" in err
    bare = tmp_path / "bare.toml"
    bare.write_text("[tracker]\n")
    assert main(["replay", str(path), "--tracker-config", str(bare), "--json"]) == 2
    assert "no space of interest" in capsys.readouterr().err


def test_bearing_percentiles_are_of_the_magnitude():
    """A signed error's percentile mixes its two sides (p95 -0.82 beside rms 2.30): p95 and max are
    of |error|, the signed mean is given apart."""
    from foveatrack.replay import _stats

    x = np.array([-3.0] * 50 + [0.5] * 50)
    s = _stats(x)
    assert s["p95"] == 3.0 and s["max"] == 3.0 and s["mean_signed"] == -1.25
    assert s["rms"] == pytest.approx(np.sqrt((9 * 50 + 0.25 * 50) / 100))
    assert "|error|" in s["of"]


def test_the_open_loop_caveat_sits_beside_the_numbers(sim_run, tmp_path):
    from foveatrack.replay import format_report

    path, _, _ = sim_run
    cfg = tmp_path / "tight.toml"
    cfg.write_text(SCENE.read_text().replace("deadband_deg = 2.0", "deadband_deg = 0.5"))
    lines = format_report(replay(path, str(cfg))).splitlines()
    err_line = next(x for x in lines if x.lstrip().startswith("tracking error"))
    assert "open loop" in err_line
    # the dead reckoning follows the recorded head (7188342), so the reconstruction is a figure on the
    # recorded motion, with the same caveat; it once mixed two heads (rms 22.9 m) and was withheld
    rec_line = next(x for x in lines if x.lstrip().startswith("reconstructed target position"))
    assert rec_line.lstrip().startswith("reconstructed target position error [m]: rms ")
    assert "open loop" in rec_line and "not comparable" not in rec_line
    same = format_report(replay_recording(path)).splitlines()
    assert not any("open loop" in x for x in same)
    same_rec = next(x for x in same if x.lstrip().startswith("reconstructed target position error [m]"))
    # same points (the detections do not depend on the deadband), placed from the same head motion:
    # the same figure as the recorded configuration's replay
    assert rec_line.split(" (open loop")[0] == same_rec
    # the tracking error too is the recorded head's: acquired by the recorded run's dead band (this
    # config's 0.5 deg + 1 never held on a head that ran a 2 deg dead band: "acquisition n/a")
    same_err = next(x for x in same if x.lstrip().startswith("tracking error"))
    assert err_line.split(" (open loop")[0] == same_err.split(" (open loop")[0]
    assert "acquisition n/a" not in err_line


def test_replay_plot_of_a_recording_without_frames_draws_nothing_and_says_so(tmp_path, capsys):
    # four blank figures and exit 0 read as a run drawn
    empty = Path(__file__).resolve().parents[1] / "corpus" / "no-frames.mcap"
    assert main(["replay", str(empty), "--plot", str(tmp_path / "plots")]) == 0
    assert "--plot: no plots, the recording holds no lidar frames" in capsys.readouterr().out
    assert not (tmp_path / "plots").exists()
