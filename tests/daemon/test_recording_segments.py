"""A daemon recording split into segments (``[recording] segment_minutes``, issue 26: the MCAP writer
keeps an index entry per chunk until its file closes, so a long run's memory is bounded only by
closing files).  Through the real processes on loopback: each segment is a complete recording with
its own command journal, no frame is lost or doubled at a boundary, and replay of the first segment
reads the run whole and reproduces it to the bit."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from daemon_procs import ROOT, env, log_events, stop_all, terminate
from foveatrack.errors import UserError
from foveatrack.live_devices import journal_path, read_journal
from foveatrack.recording import RecordingReader
from foveatrack.recording.segments import first_segment, following_segments, open_run, segment_path
from test_faults import _replays_to_the_bit, _setup, _wait_frames

pytestmark = [pytest.mark.slow, pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs a pty")]


def test_segment_names_sort_after_the_first_and_name_it_back(tmp_path):
    first = tmp_path / "20261128T060000Z.mcap"
    names = [segment_path(first, k) for k in range(12)]
    assert names[0] == first and names[3].name == "20261128T060000Z.part0003.mcap"
    assert sorted(p.name for p in names) == [p.name for p in names]
    assert all(first_segment(p) == (first, k) for k, p in enumerate(names))


def test_a_daemon_run_in_segments_is_whole_and_replays_to_the_bit(tmp_path):
    procs, link, truth, rec, log, bport = _setup(tmp_path, recording_extra="segment_minutes = 0.03")   # 1.8 s
    try:
        # at least three boundaries while tracking
        _wait_frames(log, rec, 15, list(procs.values()))
        for _ in range(60):
            if sum(e["event"] == "recording_segment" for e in log_events(log)) >= 3:
                break
            _wait_frames(log, rec, 5, list(procs.values()))
        assert terminate(procs["daemon"]) == 0, (tmp_path / "d.err").read_text()
    finally:
        stop_all(procs)
    start = next(e for e in log_events(log) if e["event"] == "start")
    assert start["heap_returns_freed"] is sys.platform.startswith("linux"), start   # foveatrack.daemon.heap
    events = [e for e in log_events(log) if e["event"] == "recording_segment"]
    parts = following_segments(rec)
    assert len(parts) >= 3 and [e["index"] for e in events] == list(range(1, len(parts) + 1)), events
    assert [e["path"] for e in events] == [str(p) for p in parts]
    frames, n_journal = [], 0
    for k, p in enumerate([rec, *parts]):
        r = RecordingReader(p)
        assert r.closed() and r.info.get("segment_index") == (None if k == 0 else str(k)), p
        assert oct(p.stat().st_mode & 0o777) == "0o600"
        ids = [d["frame_index"] for d in r.records("detections")]
        assert ids, f"segment {k} holds no frame"
        frames += ids
        # each segment's journal holds exactly the commands its file does (those the dead reckoning sent)
        lines, bad = read_journal(journal_path(p))
        assert not bad
        recorded = [c["raw_hex"] for c in r.records("commands")]
        assert recorded == [j.raw.hex() for j in lines if j.source not in ("", "homing")], k
        n_journal += len(lines)
    # no frame lost or doubled at a boundary (the daemon's count at its stop)
    stop = next(e for e in log_events(log) if e["event"] == "stop")
    assert frames == list(range(len(frames))) and len(frames) == stop["stats"]["frames"], (len(frames), stop["stats"])
    # the heap trimmed once per segment closed, on the writer's thread (foveatrack.daemon.heap), where glibc's is
    assert stop["stats"].get("heap_trims", 0) == (len(parts) if start["heap_returns_freed"] else 0), stop["stats"]
    # replay reads the run whole from its first segment, and reproduces it
    run = open_run(rec)
    assert len(run.parts) == len(parts) + 1 and not run.notes
    assert sum(1 for _ in run.points()) == len(frames) and run.complete and run.problem is None
    _replays_to_the_bit(rec)
    # recover finds nothing to do in any of them
    out = subprocess.run([sys.executable, "-m", "foveatrack", "recover", str(rec), *map(str, parts)], cwd=ROOT, env=env(),
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0 and out.stdout.count("nothing to recover") == len(parts) + 1, out
    # a later segment alone: replay says which file to give; export takes it alone
    with pytest.raises(UserError, match=f"give the run's first segment \\({rec.name}\\)"):
        open_run(parts[1])
    assert open_run(parts[1], segment_alone=True).info["segment_index"] == "2"
    print(f"{len(parts) + 1} segments, {len(frames)} frames, {n_journal} journal lines")
