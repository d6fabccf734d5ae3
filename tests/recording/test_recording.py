"""Recordings: round trip, crash safety (kill -9, every truncation offset), clear errors, export."""

import csv
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from child_procs import dies_with_this_process
from failing_writes import FailingFlush, metadata_write_fails

from foveatrack.errors import UserError
from foveatrack.recording import (
    RecordingReader,
    RecordingWriter,
    export_points,
    export_trajectory,
)
from foveatrack.recording.format import VIEW_CHANNELS

ROOT = Path(__file__).resolve().parents[2]
META = {"scene_toml": "[scene]\nname = 'x'\n", "seed": 42, "params": {"deadband_deg": 0.5}}


def frame(rng, k, n):
    t = 1_000_000_000 + k * 100_000_000
    xyz = rng.normal(0, 50, (n, 3))
    tp = t - 100_000_000 + np.sort(rng.integers(0, 100_000_000, n))
    refl = rng.integers(0, 256, n).astype(np.uint8)
    return t, xyz, tp, refl


def write_sample(path, n_frames=5, n_points=200, **kw):
    rng = np.random.default_rng(0)
    frames = []
    with RecordingWriter(path, META, **kw) as w:
        for k in range(n_frames):
            t, xyz, tp, refl = frame(rng, k, n_points)
            frames.append((t, xyz, tp, refl))
            w.write_points(t, k, xyz, tp, refl)
            w.write_detection(t + 1000, k, k % 2 == 0, xyz_m=[1.0, 2.0, k] if k % 2 == 0 else None, n_points=3)
            w.write_command(t + 2000, b"\xff\x01\x00\x04\x20\x00\x25", note="left")
            w.write_head_estimate(t + 3000, pan_deg=0.1 * k, tilt_deg=-0.2 * k)
            w.write_truth(t, target_xyz_m=[100.0, 1.0, 2.0], pan_deg=0.0)
            w.write_metric(t + 4000, "proc_ms", 1.5 + k)
    return frames


def test_round_trip_is_exact(tmp_path):
    p = tmp_path / "r.mcap"
    frames = write_sample(p)
    r = RecordingReader(p)
    assert r.meta == META
    assert r.info["format_version"] == "4" and "numpy_version" in r.info
    got = list(r.points())
    assert r.complete and r.problem is None
    assert len(got) == len(frames)
    for f, (t, xyz, tp, refl) in zip(got, frames):
        assert f.t_ns == t
        np.testing.assert_array_equal(f.xyz, xyz)  # float64: bit-exact
        np.testing.assert_array_equal(f.t_ns_points, tp)
        np.testing.assert_array_equal(f.reflectivity, refl)
    assert [f.frame_index for f in got] == list(range(5))
    dets = r.records("detections")
    assert dets[0]["xyz_m"] == [1.0, 2.0, 0.0] and dets[1]["xyz_m"] is None and dets[1]["detected"] is False
    cmd = r.records("commands")[0]
    assert bytes.fromhex(cmd["raw_hex"]) == b"\xff\x01\x00\x04\x20\x00\x25" and cmd["note"] == "left"
    assert cmd["t_ns"] == frames[0][0] + 2000
    assert {k: v for k, v in r.channels().items() if k not in VIEW_CHANNELS} == {"points": 5, "detections": 5, "commands": 5, "head": 5, "truth": 5, "metrics": 5}
    # messages come back in the order they were written
    assert [m.channel for m in r.messages()][:6] == ["points", "detections", "commands", "head", "truth", "metrics"]


def test_float32_points_round_to_the_mm_and_zstd(tmp_path):
    # points_dtype="float32": every frame in the compact mm-grid encoding, points off the grid rounded
    # to the nearest mm (as a Livox would have reported them)
    p = tmp_path / "r.mcap"
    frames = write_sample(p, points_dtype="float32", compression="zstd")
    got = list(RecordingReader(p).points())
    for f, (_, xyz, tp, _) in zip(got, frames):
        np.testing.assert_array_equal(f.xyz, np.rint(xyz * 1000) * 1e-3)
        assert np.abs(f.xyz - xyz).max() <= 0.5e-3
        np.testing.assert_array_equal(f.t_ns_points, tp)


def test_existing_file_is_not_overwritten(tmp_path):
    p = tmp_path / "r.mcap"
    p.write_text("precious")
    with pytest.raises(UserError, match="already exists"):
        RecordingWriter(p, {})
    assert p.read_text() == "precious"
    RecordingWriter(p, {}, overwrite=True).close()
    assert RecordingReader(p).meta == {}


@pytest.mark.slow
def test_every_truncation_reads_a_prefix_of_whole_frames(tmp_path):
    p = tmp_path / "full.mcap"
    with RecordingWriter(p, {"seed": 3}) as w:  # three chunks of one frame + its detection
        for k in range(3):
            w.write_points(10 + k, k, np.full((2, 3), k), [10 + k] * 2, [7, 8])
            w.write_detection(11 + k, k, True, xyz_m=[k, 0, 0])
        w.flush()
        size_before_close = p.stat().st_size
    data = p.read_bytes()
    full = [(m.channel, m.t_ns, m.record if m.channel != "points" else m.record.t_ns)
            for m in RecordingReader(p).messages()]
    cut_path = tmp_path / "cut.mcap"
    last_n = 0
    meta_end = incomplete_upto = None
    for cut in range(len(data) + 1):
        cut_path.write_bytes(data[:cut])
        try:
            r = RecordingReader(cut_path)
        except UserError as exc:
            assert str(cut_path) in str(exc)
            assert meta_end is None, f"metadata readable at {meta_end} but not at {cut}"
            continue
        if meta_end is None:
            meta_end = cut
        got = [(m.channel, m.t_ns, m.record if m.channel != "points" else m.record.t_ns) for m in r.messages()]
        assert got == full[: len(got)], cut
        assert len(got) >= last_n  # more file never gives fewer messages
        last_n = len(got)
        # whole frames only: a points message always comes with everything written after it
        n_points = sum(1 for g in got if g[0] == "points")
        assert len(got) == 2 * n_points, cut
        if not r.complete:
            assert r.problem and "byte" in r.problem
            incomplete_upto = cut
    assert last_n == len(full) and r.complete
    assert incomplete_upto >= size_before_close  # only close() marks the data complete
    assert meta_end is not None and meta_end < 600   # header + metadata (with the channel table)


WRITER_SCRIPT = textwrap.dedent(
    """
    import sys, numpy as np
    from foveatrack.recording import RecordingWriter
    w = RecordingWriter(sys.argv[1], {"seed": 1})
    rng = np.random.default_rng(0)
    k = 0
    while True:
        xyz = rng.normal(0, 10, (2000, 3))
        t = 1_000 + k * 100_000_000
        w.write_points(t, k, xyz, np.full(2000, t), np.zeros(2000, np.uint8))
        w.write_detection(t, k, True, xyz_m=xyz.mean(0))
        w.flush()
        print(k, flush=True)
        k += 1
    """
)


def test_readable_after_kill_9(tmp_path):
    p = tmp_path / "killed.mcap"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen(dies_with_this_process([sys.executable, "-c", WRITER_SCRIPT, str(p)]), stdout=subprocess.PIPE,
                            text=True, env=env)
    try:
        done = -1
        while done < 8:
            done = int(proc.stdout.readline())
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(5)
    r = RecordingReader(p)
    frames = list(r.points())
    dets = r.records("detections")
    assert not r.complete
    assert len(frames) >= done + 1  # every frame reported flushed is there
    assert [f.frame_index for f in frames] == list(range(len(frames)))
    assert len(dets) == len(frames)
    for f, d in zip(frames, dets):
        np.testing.assert_allclose(d["xyz_m"], f.xyz.mean(0))


def test_non_recordings_give_clear_errors(tmp_path):
    missing = tmp_path / "nope.mcap"
    with pytest.raises(UserError, match="nope.mcap.*does not exist"):
        RecordingReader(missing)
    txt = tmp_path / "notes.txt"
    txt.write_text("hello, I am not a recording\n")
    with pytest.raises(UserError, match=r"notes.txt is not a foveatrack recording.*MCAP magic"):
        RecordingReader(txt)
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    with pytest.raises(UserError, match="empty"):
        RecordingReader(empty)
    from mcap.writer import Writer

    other = tmp_path / "other.mcap"
    with open(other, "wb") as fh:
        w = Writer(fh)
        w.start()
        w.add_metadata("something", {"a": "b"})
        w.finish()
    with pytest.raises(UserError, match="other.mcap is not a foveatrack recording"):
        RecordingReader(other)


def test_an_mcap_of_another_program_is_named_so_not_cut_short(tmp_path):
    """A valid MCAP written by the official writer, with messages and no foveatrack metadata, was
    called "cut short (kill -9 or power loss)": the reader stopped at its first message and took the
    file for unfinished.  It is named for what it is, on one line, and one of ours cut short before
    its metadata still says so."""
    from mcap.writer import Writer

    other = tmp_path / "ros.mcap"
    with open(other, "wb") as fh:
        w = Writer(fh)
        w.start(profile="ros2", library="someone-else 1.0")
        sid = w.register_schema(name="X", encoding="jsonschema", data=b"{}")
        cid = w.register_channel(topic="/x", message_encoding="json", schema_id=sid)
        for i in range(3):
            w.add_message(cid, log_time=i, data=b'{"a": 1}', publish_time=i)
        w.finish()
    with pytest.raises(UserError) as exc:
        RecordingReader(other)
    msg = str(exc.value)
    assert "\n" not in msg and "cut short" not in msg and "kill -9" not in msg
    assert "ros.mcap is not a foveatrack recording: a valid MCAP file written by 'someone-else 1.0'" in msg
    assert "(profile 'ros2') with no 'foveatrack' metadata record" in msg

    ours = tmp_path / "ours.mcap"
    write_sample(ours, n_frames=1, n_points=3)
    data = ours.read_bytes()
    meta_at = 8                       # after the magic: walk the records to the first Metadata (0x0C)
    while data[meta_at] != 0x0C:
        meta_at += 9 + int.from_bytes(data[meta_at + 1:meta_at + 9], "little")
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[:meta_at])
    with pytest.raises(UserError, match=r"cut\.mcap is a foveatrack recording \(its Header's profile\) without its "
                                        r"metadata: the file ends at byte \d+ before it, its writer not closed"):
        RecordingReader(cut)
    # cut inside the metadata record (a length that runs past the end): ours too, damaged before it
    # (before: "is not a foveatrack recording", a user's audit on a recording cut at 4 KB)
    cut.write_bytes(data[:meta_at + 20])
    with pytest.raises(UserError, match=r"cut\.mcap is a foveatrack recording \(its Header's profile\) without its "
                                        r"metadata: damaged or cut short before it \(skipped bytes"):
        RecordingReader(cut)


def test_export_points_csv_and_npz(tmp_path):
    p = tmp_path / "r.mcap"
    frames = write_sample(p, n_frames=3, n_points=10)
    assert export_points(p, tmp_path / "pts.npz") == 30
    z = np.load(tmp_path / "pts.npz")
    np.testing.assert_array_equal(z["x_m"], np.concatenate([f[1][:, 0] for f in frames]))
    np.testing.assert_array_equal(z["t_ns"], np.concatenate([f[2] for f in frames]))
    np.testing.assert_array_equal(z["frame_index"], np.repeat([0, 1, 2], 10))
    assert export_points(p, tmp_path / "pts.csv") == 30
    rows = list(csv.DictReader(open(tmp_path / "pts.csv")))
    assert len(rows) == 30 and float(rows[3]["y_m"]) == frames[0][1][3, 1]
    with pytest.raises(UserError, match=r"\.csv or \.npz"):
        export_points(p, tmp_path / "pts.txt")


def test_export_trajectory_csv_and_npz(tmp_path):
    p = tmp_path / "r.mcap"
    frames = write_sample(p, n_frames=4, n_points=5)
    n = export_trajectory(p, tmp_path / "traj.csv")
    assert n == 16  # detections, head, truth, commands
    rows = list(csv.DictReader(open(tmp_path / "traj.csv")))
    det = [r for r in rows if r["channel"] == "detections"]
    assert det[2]["xyz_m[2]"] == "2.0" and det[1]["xyz_m[0]"] == ""
    export_trajectory(p, tmp_path / "traj.npz", channels=("head", "detections"))
    z = np.load(tmp_path / "traj.npz")
    np.testing.assert_allclose(z["head.pan_deg"], [0.0, 0.1, 0.2, 0.3])
    np.testing.assert_array_equal(z["head.t_ns"], [f[0] + 3000 for f in frames])
    assert np.isnan(z["detections.xyz_m[0]"][1])


def test_a_damaged_last_chunk_is_skipped_and_reported(tmp_path):
    p = tmp_path / "r.mcap"
    with RecordingWriter(p, {}) as w:
        for k in range(3):
            w.write_points(10 + k, k, np.full((50, 3), float(k)), [10 + k] * 50, np.zeros(50))
            w.flush()
            if k == 1:
                start_last = p.stat().st_size
    data = bytearray(p.read_bytes())
    data[start_last + 80] ^= 0xFF  # inside the third chunk's compressed records
    q = tmp_path / "bad.mcap"
    q.write_bytes(data)
    r = RecordingReader(q)
    assert [f.frame_index for f in r.points()] == [0, 1]
    assert r.complete   # the writer closed it: the damage is reported, not taken for a cut
    (d,) = r.damage
    assert d.lost == {"points": 1} and d.lost_exact and d.start_byte == start_last
    assert r.problem.startswith(f"skipped bytes {start_last}-") and "1 frame and 0 other records lost" in r.problem


def test_a_binary_channel_of_a_later_version_is_read_past_not_taken_for_damage(tmp_path):
    # A recording with a channel this version does not know, protobuf-encoded (as /imu was new once):
    # its bytes come through as they are, a JSON channel it does not know as records, the rest as usual.
    import foxglove

    path = tmp_path / "later.mcap"
    with RecordingWriter(path, {"seed": 1}, created_utc="fixed") as w:
        w.write_detection(1_000, 0, False)
        later = foxglove.Channel("/later_binary", message_encoding="protobuf", context=w.context,
                                 schema=foxglove.Schema(name="x.Later", encoding="protobuf", data=b""))
        later.log(b"\x08\x96\x01\xff", log_time=2_000)
        w.write("later_json", 3_000, {"a": 1})
    msgs = list(RecordingReader(path).messages())
    got = {m.channel: m.record for m in msgs}
    assert got["later_binary"] == b"\x08\x96\x01\xff"
    assert got["later_json"] == {"t_ns": 3_000, "a": 1}
    assert got["detections"]["detected"] is False


def test_csv_columns_are_written_as_csv_writer_writes_them(tmp_path):
    """The block writer of numeric columns gives the bytes of csv.writer row by row (str of each
    number, \\r\\n, a NaN as an empty cell on request), over more than one block."""
    import math

    from foveatrack.recording import export

    rng = np.random.default_rng(0)
    n = export._CSV_BLOCK_ROWS + 17
    cols = {"i": rng.integers(-2**62, 2**62, n), "f64": rng.normal(size=n),
            "f32": rng.normal(size=n).astype(np.float32), "u8": rng.integers(0, 255, n).astype(np.uint8),
            "b": rng.random(n) < 0.5, "nan": np.where(rng.random(n) < 0.2, np.nan, rng.random(n)),
            "odd": np.resize([np.inf, -np.inf, -0.0, 1e-300, 1e300], n)}
    for nan_as_empty in (False, True):
        want = tmp_path / "want.csv"
        with open(want, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(cols)
            for row in zip(*(c.tolist() for c in cols.values())):
                w.writerow(["" if nan_as_empty and isinstance(v, float) and math.isnan(v) else v for v in row])
        export.write_columns(tmp_path / "got.csv", cols, nan_as_empty)
        assert (tmp_path / "got.csv").read_bytes() == want.read_bytes()


@pytest.fixture(scope="module")
def every_table(tmp_path_factory):
    """A recording with what every export writes: points, records, IMU samples, tracks, object truth."""
    from foveatrack.recording.format import TRACKS, TRUTH_OBJECTS
    from foveatrack.recording.records import ObjectTruthRecord, TrackEntry, TracksRecord

    p = tmp_path_factory.mktemp("tables") / "r.mcap"
    rng = np.random.default_rng(1)
    with RecordingWriter(p, META) as w:
        for k in range(6):
            t, xyz, tp, refl = frame(rng, k, 300)
            w.write_points(t, k, xyz, tp, refl)
            w.write_detection(t + 1000, k, k % 2 == 0, xyz_m=[1.0, 2.0, k] if k % 2 == 0 else None, n_points=3)
            w.write_head_estimate(t + 3000, pan_deg=0.1 * k, tilt_deg=-0.2 * k)
            w.write_imu(t, k, t / 1e9 + np.arange(20) * 1e-3, rng.normal(size=(20, 3)),
                        rng.normal(size=(20, 3)) if k % 2 else None)
            tracks = tuple(TrackEntry(i, k > 1, "drone", "bird", (1.0 * i, 2.0, k), (0.5, 0.0, -0.1), True, True,
                                      0.3 * i if k > 1 else None) for i in range(3))
            w.write(TRACKS, t, TracksRecord(t, k, tracks, fixated=1, pinned=None).to_json())
            for i in ("a", "b"):
                w.write(TRUTH_OBJECTS, t, ObjectTruthRecord(t, k, i, "drone", (k, 1.0, 2.0), (0.0, 1.0, 0.0),
                                                            0.4, 7).to_json())
    return p


def _exports():
    from foveatrack.recording import export_imu, export_tracks, export_truth_objects

    return [export_points, export_trajectory, export_imu, export_tracks, export_truth_objects]


def _npz_members(path) -> dict:
    import zipfile

    with zipfile.ZipFile(path) as z:
        return {n: z.read(n) for n in z.namelist()}


@pytest.mark.parametrize("ext", ["csv", "npz"])
@pytest.mark.parametrize("export_fn", _exports(), ids=lambda f: f.__name__)
def test_an_export_cut_short_leaves_nothing_under_its_name(every_table, tmp_path, monkeypatch, export_fn, ext):
    """A Ctrl-C halfway through the writing (a user's left 917 505 of 1 251 727 CSV lines, and an NPZ
    that would not decompress, under the final names): neither the file nor a temporary is left."""
    from cut_short import cut_short_open

    from foveatrack.recording import export

    whole = tmp_path / f"whole.{ext}"
    export_fn(every_table, whole)
    monkeypatch.setattr(export, "open", cut_short_open(whole.stat().st_size // 2), raising=False)
    with pytest.raises(KeyboardInterrupt):
        export_fn(every_table, tmp_path / f"cut.{ext}")
    assert sorted(p.name for p in tmp_path.iterdir()) == [whole.name]


@pytest.mark.parametrize("ext", ["csv", "npz"])
@pytest.mark.parametrize("export_fn", _exports(), ids=lambda f: f.__name__)
def test_an_export_writes_what_it_wrote_straight_to_its_name(every_table, tmp_path, monkeypatch, export_fn, ext):
    """Through the temporary, the bytes written straight to the name before (an NPZ's members: the zip's
    entry times are the clock's)."""
    import contextlib

    from foveatrack.recording import export

    export_fn(every_table, tmp_path / f"through_temporary.{ext}")
    monkeypatch.setattr(export, "written_whole", contextlib.contextmanager(lambda p: (yield p)))
    export_fn(every_table, tmp_path / f"straight.{ext}")
    got, want = tmp_path / f"through_temporary.{ext}", tmp_path / f"straight.{ext}"
    if ext == "csv":
        assert got.read_bytes() == want.read_bytes()
    else:
        assert _npz_members(got) == _npz_members(want)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([got.name, want.name])


def test_export_of_tables_a_damaged_record_is_named_and_nothing_is_left_when_one_is_missing(tmp_path, capsys):
    # a review found: a tracks or object-truth record of the wrong type came out as a traceback, and
    # `--imu F --tracks G` of a single-target run wrote F before finding it had no tracks
    from foveatrack.cli import main
    from foveatrack.recording.format import TRACKS, TRUTH_OBJECTS

    rng = np.random.default_rng(1)
    bad = tmp_path / "bad.mcap"
    with RecordingWriter(bad, META) as w:
        t, xyz, tp, refl = frame(rng, 0, 100)
        w.write_points(t, 0, xyz, tp, refl)
        w.write(TRACKS, t, {"frame_id": 0, "tracks": [{"id": "seven", "confirmed": True}]})
        w.write(TRUTH_OBJECTS, t, {"frame_id": 0, "id": "a", "class": "drone", "xyz_m": "here"})
    for flag, channel in (("--tracks", "tracks"), ("--truth-objects", "truth_objects")):
        assert main(["export", str(bad), flag, str(tmp_path / "o.csv")]) == 2
        err = capsys.readouterr().err
        assert f"bad.mcap: a {channel} record at time {t} ns is damaged" in err and "Traceback" not in err, err
    single = tmp_path / "single.mcap"
    with RecordingWriter(single, META) as w:
        for k in range(3):
            t, xyz, tp, refl = frame(rng, k, 100)
            w.write_points(t, k, xyz, tp, refl)
            w.write_imu(t, k, t / 1e9 + np.arange(20) * 1e-3, rng.normal(size=(20, 3)), None)
    out = tmp_path / "out"
    out.mkdir()
    assert main(["export", str(single), "--imu", str(out / "imu.csv"), "--tracks", str(out / "tracks.csv"),
                 "--csv", str(out / "points.csv")]) == 2
    assert "holds no tracks" in capsys.readouterr().err
    assert list(out.iterdir()) == []
    assert main(["export", str(single), "--imu", str(out / "imu.csv")]) == 0
    assert (out / "imu.csv").read_text().count("\n") == 61


DISK_FULL_SCRIPT = textwrap.dedent(
    """
    import resource, signal, sys
    import numpy as np
    from foveatrack.recording import RecordingWriter
    from foveatrack.recording.pack_kernels import pack_points

    pack_points(np.zeros((1, 3)), 0, np.zeros(1, np.int64), np.zeros(1, np.uint8))   # kernels loaded first
    # the file may not grow past 300 kB: a write past it fails (EFBIG) as on a full disk, for root too
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (300_000, 300_000))
    rng = np.random.default_rng(0)
    w = RecordingWriter(sys.argv[1], {"seed": 1}, compression="none")
    try:
        for k in range(100):
            t = 1_000_000_000 + k * 100_000_000
            w.write_points(t, k, rng.normal(0, 50, (2000, 3)), np.full(2000, t - 50_000_000))
            w.write_detection(t, k, False)
    except Exception as exc:
        print("KEPT", getattr(exc, "frames_kept", None))
        print(type(exc).__name__, exc)
    try:
        w.close()        # after the failure: lets the file go as it is, raises nothing more
    except Exception as exc:
        print("CLOSE RAISED", exc)
    print("CLOSED", flush=True)
    """
)


def test_a_write_that_fails_part_way_says_what_is_kept_and_keeps_it(tmp_path):
    """A recording whose disk fills (here: a file-size limit, a real failed write, root or not) used
    to end in the SDK's "RuntimeError: FoxgloveError: MCAP error: I/O error from writing", a second
    traceback from close(), and a Rust panic at the interpreter's exit (the failed SDK writer
    dropped then).  Now: one UserError naming the file and what it keeps, which a reader gets."""
    p = tmp_path / "full.mcap"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    r = subprocess.run([sys.executable, "-c", DISK_FULL_SCRIPT, str(p)], capture_output=True, text=True,
                       env=env, timeout=120)
    assert r.returncode == 0 and "CLOSED" in r.stdout, r.stdout + r.stderr
    assert "panicked" not in r.stderr and "Failed to close" not in r.stderr, r.stderr
    assert "RecordingWriteError" in r.stdout and "CLOSE RAISED" not in r.stdout, r.stdout
    kept = int(r.stdout.split("KEPT ")[1].split()[0])
    assert 0 < kept < 100
    assert f"cannot write recording {p}" in r.stdout and f"the {kept} frame(s) written before are kept" in r.stdout
    frames = list(RecordingReader(p).points())
    assert [f.frame_index for f in frames] == list(range(kept))




def test_a_full_disk_is_said_in_words(tmp_path, monkeypatch):
    """The SDK's error does not carry the OS's errno: a full disk is told by the file system's free
    space (os.statvfs simulated full here)."""
    from types import SimpleNamespace

    import foveatrack.recording.writer as writer_mod

    p = tmp_path / "r.mcap"
    rng = np.random.default_rng(0)
    w = RecordingWriter(p, META)
    for k in range(3):
        t, xyz, tp, refl = frame(rng, k, 100)
        w.write_points(t, k, xyz, tp, refl)

    w._w = FailingFlush(w._w)
    monkeypatch.setattr(writer_mod.os, "statvfs", lambda _p: SimpleNamespace(f_bavail=3, f_frsize=4096))
    with pytest.raises(UserError, match=r"no space left on its disk \(12,288 bytes free"):
        t, xyz, tp, refl = frame(rng, 3, 100)
        w.write_points(t, 3, xyz, tp, refl)
    with pytest.raises(UserError, match="cannot write recording"):     # and the same for any call after it
        w.write_detection(t, 3, False)
    w.close()
    assert w.write_error.frames_kept == 2        # the third frame waited in the chunk that failed


def test_a_recording_whose_metadata_does_not_fit_leaves_no_empty_file(tmp_path, monkeypatch):
    """On a full disk the new file's first write fails: an empty file was left and called a recording
    whose "0 frame(s) written before are kept and readable" (replay then said it was empty).
    Simulated: the OS's ENOSPC raised where the SDK writes the metadata."""
    import errno

    metadata_write_fails(monkeypatch, errno.ENOSPC)
    p = tmp_path / "r.mcap"
    with pytest.raises(UserError) as exc:
        RecordingWriter(p, META)
    assert str(exc.value).startswith(f"cannot create recording {p}: no space left on its disk")
    assert "nothing was left under its name" in str(exc.value) and not p.exists()


def test_a_failed_write_in_a_later_segment_counts_that_files_frames(tmp_path):
    """'the N frame(s) written before are kept' named the segment's file but counted the run's frames:
    11 said of a file holding 1."""
    rng = np.random.default_rng(0)
    w = RecordingWriter(tmp_path / "a.mcap", META)
    for k in range(10):
        t, xyz, tp, refl = frame(rng, k, 50)
        w.write_points(t, k, xyz, tp, refl)
    w.next_segment(tmp_path / "b.mcap")
    for k in range(10, 12):
        t, xyz, tp, refl = frame(rng, k, 50)
        w.write_points(t, k, xyz, tp, refl)
    w._w = FailingFlush(w._w)
    with pytest.raises(UserError) as exc:
        t, xyz, tp, refl = frame(rng, 12, 50)
        w.write_points(t, 12, xyz, tp, refl)
    w.close()
    kept = len(list(RecordingReader(tmp_path / "b.mcap").points()))
    assert kept == 1 and w.write_error.frames_kept == kept
    assert str(exc.value).startswith(f"cannot write recording {tmp_path / 'b.mcap'}:")
    assert "the 1 frame(s) written before are kept" in str(exc.value), str(exc.value)
    assert len(list(RecordingReader(tmp_path / "a.mcap").points())) == 10


def test_a_segment_whose_metadata_does_not_fit_leaves_no_empty_file(tmp_path, monkeypatch):
    """As for the first file: the new segment's empty file was left on the full disk and said to keep
    the frames written before."""
    import errno

    rng = np.random.default_rng(0)
    w = RecordingWriter(tmp_path / "c.mcap", META)
    for k in range(5):
        t, xyz, tp, refl = frame(rng, k, 50)
        w.write_points(t, k, xyz, tp, refl)

    metadata_write_fails(monkeypatch, errno.ENOSPC)
    e = tmp_path / "e.mcap"
    with pytest.raises(UserError) as exc:
        w.next_segment(e)
    monkeypatch.undo()
    assert str(exc.value).startswith(f"cannot create recording {e}: no space left on its disk")
    assert "nothing was left under its name" in str(exc.value) and not e.exists()
    with pytest.raises(UserError, match="cannot create recording"):      # and the same for any call after it
        w.write_detection(0, 0, False)
    w.close()
    assert len(list(RecordingReader(tmp_path / "c.mcap").points())) == 5
