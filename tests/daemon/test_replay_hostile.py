"""Replay and export of recordings that are valid but unusual, or damaged in ways a reader must not
trip over (issue 32): each ends in the data, the data with a warning naming what was lost, or a
one-line error; never a traceback.

* a recording with no frames (the daemon's after a run in which the lidar never sent data) is a
  valid, empty result in replay and export."""

import numpy as np

from foveatrack.cli import main
from foveatrack.replay import format_report, replay_recording

from inprocess import inprocess_daemon


class _Head:
    connected = True

    def send_frame(self, raw):
        return True


def daemon_recording_without_frames(tmp_path):
    """What the daemon leaves when the lidar never sent a point: its metadata and the stop event."""
    from foveatrack.daemon.runtime import _job_event

    d, rec = inprocess_daemon(tmp_path, _Head())
    d._record(_job_event, 0, {"event": "stop", "stats": dict(d.counters)})
    d.recorder.close()
    return rec


def test_a_daemon_recording_without_frames_replays_as_an_empty_result(tmp_path, capsys):
    rec = daemon_recording_without_frames(tmp_path)
    res = replay_recording(rec)
    assert res.frames["frame_index"].size == 0 and res.recorded["detected"].dtype == bool
    c = res.comparison
    assert c["detections_equal"] and c["commands_compared"] == 0 and not c["partial"]
    assert res.metrics["detection"]["frames"] == 0
    assert "no lidar frames" in format_report(res)
    assert main(["replay", str(rec), "--json"]) == 0
    assert main(["replay", str(rec), "--export-trajectory", str(tmp_path / "t.csv")]) == 0
    assert (tmp_path / "t.csv").read_text().count("\n") == 1          # the header only
    capsys.readouterr()


def test_a_recording_without_frames_exports_empty_files(tmp_path, capsys):
    rec = daemon_recording_without_frames(tmp_path)
    assert main(["export", str(rec), "--csv", str(tmp_path / "p.csv"), "--lvx", str(tmp_path / "p.lvx"),
                 "--npz", str(tmp_path / "p.npz"), "--trajectory", str(tmp_path / "t.csv")]) == 0
    out = capsys.readouterr().out
    assert "0 points -> " in out
    assert np.load(tmp_path / "p.npz")["t_ns"].size == 0


def test_intact_chunks_out_of_order_are_skipped_and_named_not_a_traceback(sim_recording, tmp_path, capsys):
    """64 KiB of the file's second half copied over an earlier stretch: the copied chunks are intact (their
    CRCs verify) but go back in time after them; replay skipped nothing and crashed with "commands must
    come in time order".  Now the frames the tracker cannot take are skipped, counted and named."""
    from mcap.reader import make_reader

    path, log, _ = sim_recording
    data = bytearray(open(path, "rb").read())
    # two whole chunks (with their message indexes) of the middle copied over the chunks a fifth in:
    # at chunk boundaries, so the copies are intact whatever size a chunk has (a fixed 64 KiB held a
    # whole chunk of format 3 but none of format 4's larger ones)
    with open(path, "rb") as fh:
        cks = sorted(c.chunk_start_offset for c in make_reader(fh).get_summary().chunk_indexes)
    src, end, dst = cks[len(cks) // 2], cks[len(cks) // 2 + 2], cks[len(cks) // 5]
    data[dst:dst + end - src] = data[src:end]
    bad = tmp_path / "ooo.mcap"
    bad.write_bytes(bytes(data))
    res = replay_recording(bad)
    t = res.frames["t_end_s"]
    assert np.all(np.diff(t) > 0)
    c = res.comparison
    assert c["partial"] and any("out of time order" in d for d in c["recording_damage"])
    assert c["before_first_gap"]["detections_equal"] and c["before_first_gap"]["commands_equal"]
    assert main(["replay", str(bad)]) == 0
    out = capsys.readouterr().out
    assert "WARNING" in out and "out of time order" in out


def test_export_reports_damage_as_replay_does(sim_recording, tmp_path, capsys):
    """One flipped bit: replay said "1 frame and 9 other records lost" while export --csv / --lvx
    printed their point counts with rc 0, a frame short, and nothing else."""
    from mcap.reader import make_reader

    path, log, _ = sim_recording
    with open(path, "rb") as fh:
        cks = sorted(c.chunk_start_offset for c in make_reader(fh).get_summary().chunk_indexes)
    data = bytearray(open(path, "rb").read())
    data[cks[len(cks) // 3] + 9 + 24] ^= 0x01          # one bit of a chunk's CRC
    bad = tmp_path / "flip.mcap"
    bad.write_bytes(bytes(data))
    damage = replay_recording(bad).comparison["recording_damage"]
    assert len(damage) == 1 and "1 frame and" in damage[0]
    capsys.readouterr()
    for flag, out in (("--csv", "p.csv"), ("--lvx", "p.lvx"), ("--npz", "p.npz"), ("--trajectory", "t.csv")):
        assert main(["export", str(bad), flag, str(tmp_path / out)]) == 0
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("WARNING: damaged recording") and damage[0] in err[0], (flag, err)
