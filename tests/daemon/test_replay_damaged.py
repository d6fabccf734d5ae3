"""Replay of a damaged recording: the frames after a damaged chunk are replayed too, the report says
in one line what was skipped, and a gap with lost commands makes the comparison say it is partial
(the replay's dead reckoning lacks the commands sent in the missing frames) instead of passing off
the differences after the gap as the tracker's."""

import json
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from foveatrack.cli import main
from foveatrack.replay import format_report, replay_recording



@pytest.fixture(scope="module")
def sim_run(sim_recording):
    path, log, _ = sim_recording
    with open(path, "rb") as fh:
        cks = sorted((c.chunk_start_offset, c.chunk_length) for c in make_reader(fh).get_summary().chunk_indexes)
    return path, log, cks


def corrupt(src, dst, chunk_starts, offset=9 + 24):
    data = bytearray(Path(src).read_bytes())
    for s in chunk_starts:
        data[s + offset] ^= 0xA5           # the chunk's CRC field
    Path(dst).write_bytes(bytes(data))
    return dst


def test_a_damaged_chunk_is_skipped_and_the_frames_after_it_replayed(sim_run, tmp_path):
    path, log, cks = sim_run
    n = len(log["t_end_s"])
    assert len(cks) == n                   # one chunk per frame
    k = n // 4                             # in the first third
    res = replay_recording(corrupt(path, tmp_path / "bad.mcap", [cks[k][0]]))
    fi = res.frames["frame_index"]
    assert fi.tolist() == [i for i in range(n) if i != k]
    c = res.comparison
    assert c["partial"] and c["frames_missing"] == 1
    (gap,) = c["gaps"]
    assert (gap["after_frame"], gap["before_frame"], gap["frames_missing"]) == (k - 1, k + 1, 1)
    assert gap["head_estimate_diff_deg"] is not None and np.isfinite(gap["head_estimate_diff_deg"])
    # before the gap the replay is still the recording, to the bit
    assert c["before_first_gap"]["detections_equal"] and c["before_first_gap"]["commands_equal"]
    assert c["before_first_gap"]["frames"] == k
    assert np.array_equal(res.frames["detected"][:k], log["detected"][:k])
    text = format_report(res)
    warn = [ln for ln in text.splitlines() if "WARNING" in ln]
    assert len(warn) == 1 and f"bytes {cks[k][0]}-" in warn[0] and "1 frame" in warn[0]
    assert "comparison is partial" in text and f"frame {k}" in text


def test_a_damaged_first_chunk_leaves_a_leading_gap(sim_run, tmp_path):
    path, log, cks = sim_run
    n = len(log["t_end_s"])
    res = replay_recording(corrupt(path, tmp_path / "bad0.mcap", [cks[0][0]]))
    assert res.frames["frame_index"].tolist() == list(range(1, n))
    c = res.comparison
    assert c["partial"] and c["gaps"][0]["after_frame"] is None and c["gaps"][0]["before_frame"] == 1
    assert c["before_first_gap"]["frames"] == 0


def test_a_cut_short_tail_is_a_warning_but_the_comparison_stays_whole(sim_run, tmp_path):
    path, log, cks = sim_run
    k = len(cks) - 3
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(Path(path).read_bytes()[: cks[k][0] + cks[k][1] // 2])
    res = replay_recording(cut)
    assert res.frames["frame_index"].tolist() == list(range(k))
    c = res.comparison
    assert not c["partial"] and c["detections_equal"] and c["commands_equal"] and not c["recording_complete"]
    warn = [ln for ln in format_report(res).splitlines() if "WARNING" in ln]
    assert len(warn) == 1 and "cut short" in warn[0]


def test_cli_prints_one_warning_line_and_replays_the_rest(sim_run, tmp_path, capsys):
    path, log, cks = sim_run
    n = len(log["t_end_s"])
    bad = corrupt(path, tmp_path / "bad2.mcap", [cks[3][0], cks[4][0]])
    assert main(["replay", str(bad)]) == 0
    out = capsys.readouterr().out
    assert f"{n - 2} frames" in out.splitlines()[0]
    warn = [ln for ln in out.splitlines() if "WARNING" in ln]
    assert len(warn) == 1 and "2 frames" in warn[0] and "Traceback" not in out
    assert "comparison is partial" in out
    assert main(["replay", str(bad), "--json"]) == 0
    cap = capsys.readouterr()
    c = json.loads(cap.out)["comparison"]
    assert c["partial"] and c["frames_missing"] == 2 and len(c["recording_damage"]) == 1
    assert "WARNING: damaged recording" in cap.err, "with --json the warning still reaches a person, on stderr"
