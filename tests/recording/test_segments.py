"""Recordings split into segments (:mod:`foveatrack.recording.segments`), without processes: the
writer's file change, the recording thread's, a cut-short last segment completed by ``recover``, and
a stale file of another run beside them.  The daemon's own run in segments:
tests/daemon/test_recording_segments.py."""

import json
import os
import shutil

import numpy as np
import pytest
from mcap.reader import make_reader

from foveatrack.daemon.recover import recover
from foveatrack.daemon.support import RecordingThread
from foveatrack.recording import RecordingReader, RecordingWriter
from foveatrack.recording.segments import RunReader, open_run, segment_path

META = {"source": "daemon", "config_text": "x"}


def _frame(w, i, rng):
    t = 100_000_000 * (i + 1)
    xyz = np.round(rng.uniform(1, 5, (40, 3)) * 1000) / 1000
    w.write_points(t, i, xyz, np.linspace(t - 99_000_000, t, 40).astype(np.int64))
    w.write_detection(t, i, True, [1.0, 2.0, 3.0], 40, state="tracking")
    w.write_head_estimate(t, 0.1 * i, 0.5)
    w.write_command(t + 2_000_000, b"\xff\x01\x00\x02\x10\x00\x13", frame_id=i, source="tracker",
                    send_t_s=t * 1e-9 + 0.002)


def _summary(path):
    with open(path, "rb") as fh:
        r = make_reader(fh)
        s = r.get_summary()
        table = next(json.loads(m.metadata["channels_json"]) for m in r.iter_metadata()
                     if m.name == "foveatrack_channels")
        return {c.id: c.topic.lstrip("/") for c in s.channels.values()}, {int(k): v for k, v in table.items()}


def test_each_segment_is_a_complete_file_with_its_own_channel_table_and_d(tmp_path):
    rng = np.random.default_rng(0)
    first = tmp_path / "run.mcap"
    w = RecordingWriter(first, META)          # log time = t_ns: the keyframe's and the head's compare
    for i in range(25):
        if i in (10, 20):
            w.next_segment(segment_path(first, i // 10))
        _frame(w, i, rng)
    w.close()
    files = [segment_path(first, k) for k in range(3)]
    for k, p in enumerate(files):
        ids, table = _summary(p)          # the official reader takes each whole, summary and all
        assert table == {i: ids[i] for i in table} and set(table) == set(ids), p
        r = RecordingReader(p)
        assert r.closed() and r.info.get("segment_index") == (None if k == 0 else str(k))
        assert [d["frame_index"] for d in r.records("detections")] == list(range(10 * k, min(10 * k + 10, 25)))
        # D (the keyframe) at the segment's first head estimate: a seek into this file alone shows it
        head_t = next(m.t_ns for m in r.messages("head"))
        kf = [m.t_ns for m in r.messages("scene_keyframe")]
        assert kf and kf[0] == head_t, (k, kf[:2], head_t)
    run = open_run(first)
    assert isinstance(run, RunReader) and [d["frame_index"] for d in run.records("detections")] == list(range(25))


def test_the_recording_thread_moves_to_the_segment_of_each_job_even_after_drops(tmp_path):
    rng = np.random.default_rng(1)
    first = tmp_path / "run.mcap"
    t = RecordingThread(RecordingWriter(first, META), 1000, lambda k: segment_path(first, k))
    t.submit(_frame, 0, rng)
    t.segment = 1                  # the loop's boundary; the jobs of segment 1 are "dropped"
    t.segment = 2
    t.submit(_frame, 1, rng)       # the first job of segment 2 opens its file
    t.close()
    assert t.error is None, t.error
    assert not segment_path(first, 1).exists()
    assert RecordingReader(segment_path(first, 2)).info["segment_index"] == "2"
    assert [d["frame_index"] for d in RecordingReader(segment_path(first, 2)).records("detections")] == [1]


def test_a_cut_short_last_segment_is_completed_and_still_continues_the_run(tmp_path):
    rng = np.random.default_rng(2)
    first = tmp_path / "run.mcap"
    w = RecordingWriter(first, META, log_time="host")
    for i in range(5):
        _frame(w, i, rng)
    w.next_segment(segment_path(first, 1))
    for i in range(5, 9):
        _frame(w, i, rng)
    w.flush()
    live = segment_path(first, 1)
    cut = tmp_path / "cut.bin"
    shutil.copyfile(live, cut)        # what kill -9 leaves: no summary
    w.close()
    shutil.copyfile(cut, live)
    os.chmod(live, 0o600)
    assert not RecordingReader(live).closed()
    res = recover(live)
    assert res.recovered and res.frames == 4
    r = RecordingReader(live)
    assert r.closed() and r.info["segment_index"] == "1"
    run = open_run(first)
    assert [d["frame_index"] for d in run.records("detections")] == list(range(9)) and not run.notes


def test_a_stale_file_of_another_run_ends_the_chain_with_a_note(tmp_path):
    rng = np.random.default_rng(3)
    first = tmp_path / "run.mcap"
    other = RecordingWriter(tmp_path / "other.mcap", {**META, "config_text": "another"}, created_utc="2020-01-01T00:00:00+00:00")
    other.next_segment(segment_path(first, 2), index=2)      # a part 2 of another run, left under this name
    other.close()
    w = RecordingWriter(first, META, created_utc="2026-11-28T06:00:00+00:00")
    _frame(w, 0, rng)
    w.next_segment(segment_path(first, 1))
    _frame(w, 1, rng)
    w.close()
    run = open_run(first)
    assert len(run.parts) == 2 and "run.part0002.mcap is not segment 2 of run.mcap" in run.notes[0]
    assert "note: run.part0002.mcap" in run.warning()


def test_a_writer_without_a_file_has_no_segments(tmp_path):
    w = RecordingWriter(None, META)
    with pytest.raises(ValueError, match="without a file"):
        w.next_segment(tmp_path / "x.mcap")


@pytest.mark.parametrize("value, expect", [("60", 60.0), ("0", None), ("0.5", 0.5), ("0.001", "under 0.01"),
                                           ('"x"', "segment_minutes"), ("-1", "segment_minutes")])
def test_the_daemons_segment_minutes(tmp_path, value, expect):
    from foveatrack.daemon import load_config
    from foveatrack.errors import UserError

    p = tmp_path / "d.toml"
    p.write_text(f'[lidar]\nsensor_ip = "127.0.0.1"\nhost_ip = "127.0.0.1"\n[head]\nport = "/dev/null"\n'
                 f'[recording]\npath = "r.mcap"\nsegment_minutes = {value}\n')
    if isinstance(expect, str):
        with pytest.raises(UserError, match=expect):
            load_config(p)
    else:
        assert load_config(p).recording.segment_minutes == expect
    q = tmp_path / "default.toml"
    q.write_text(p.read_text().replace(f"segment_minutes = {value}\n", ""))
    assert load_config(q).recording.segment_minutes == 60.0      # bounded by default


def test_export_of_the_first_segment_is_the_run_and_of_a_later_one_that_segment(tmp_path):
    from foveatrack.recording.export import export_points

    rng = np.random.default_rng(4)
    first = tmp_path / "run.mcap"
    w = RecordingWriter(first, META)
    for i in range(6):
        if i == 3:
            w.next_segment(segment_path(first, 1))
        _frame(w, i, rng)
    w.close()
    assert export_points(first, tmp_path / "whole.npz") == 6 * 40
    assert export_points(segment_path(first, 1), tmp_path / "part.npz") == 3 * 40
    whole, part = np.load(tmp_path / "whole.npz"), np.load(tmp_path / "part.npz")
    assert sorted(set(whole["frame_index"])) == list(range(6))
    assert sorted(set(part["frame_index"])) == [3, 4, 5]
