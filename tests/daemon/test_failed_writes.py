"""A command whose write fails never reached the head, so the dead reckoning must not follow it.

A Pelco head latches motion: while its link is down it keeps doing what it was last told.  Before,
the daemon registered every command with the dead reckoning whether or not the bytes went out, so a
link outage read as the head following the tracker (the fault test saw ~9 deg of pan drift).  Here
the daemon runs in-process with a head link that fails for a second; the dead reckoning must equal
one fed only with the commands that were written, and replay must rebuild the same.
"""

import time

import numpy as np
import pytest

from foveatrack.control import HeadCommand
from foveatrack.recording import RecordingReader
from foveatrack.replay import replay_recording
from foveatrack.tracker import Tracker

from inprocess import inprocess_daemon, target_frame


class FlakyHead:
    """A head link whose writes fail while ``up`` is False."""

    connected = True

    def __init__(self):
        self.up = True

    def send_frame(self, raw):
        return self.up


def _run(tmp_path, down_frames):
    d, rec = inprocess_daemon(tmp_path, FlakyHead())
    for k in range(20):
        fr = target_frame(k, az_deg=10.0 if k < 10 else -10.0)   # the UAV swaps sides mid-outage
        d.head.client.up = k not in down_frames
        d.rx.offset_s = time.monotonic() - (fr.t_end_s + 0.01)      # processed 10 ms after its end
        d._process(fr, time.monotonic())
    d.recorder.close()
    return d, rec


def _written_only(d, cmds):
    """A dead reckoning told only about the commands that reached the head."""
    ref = Tracker(d.tracker.config, d.table)
    for c in cmds:
        if c["written"]:
            ref.command_sent(c["send_t_s"], HeadCommand(c["pan_dir"], c["pan_byte"], c["tilt_dir"], c["tilt_byte"]))
    return ref


def test_failed_writes_are_not_dead_reckoned(tmp_path):
    down = set(range(5, 15))
    d, rec = _run(tmp_path, down)
    cmds = [c for c in RecordingReader(rec).records("commands") if c["source"] == "tracker"]
    assert [c["written"] for c in cmds] == [k not in down for k in range(20)]
    assert d.counters["commands_failed"] == len(down)
    # During the outage the tracker kept asking for other motions (the UAV swapped sides) ...
    last_ok = (cmds[4]["pan_dir"], cmds[4]["pan_byte"])
    assert any((c["pan_dir"], c["pan_byte"]) != last_ok for c in cmds[5:15])
    # ... but the head ran the last command that reached it, and so does the dead reckoning.
    ref = _written_only(d, cmds)
    # Angles and their sigmas: the reverted command is one change of speed, not two, so it must
    # not add timing variance either (the safety gate and the world placement use the sigmas).
    times = np.linspace(0.0, 2.5, 126)
    got = np.array([d.tracker.recon.angles_at(t) for t in times])
    want = np.array([ref.recon.angles_at(t) for t in times])
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
    # the outage mattered: following the unsent commands would have put the head elsewhere
    follow = Tracker(d.tracker.config, d.table)
    for c in cmds:
        follow.command_sent(c["send_t_s"], HeadCommand(c["pan_dir"], c["pan_byte"], c["tilt_dir"], c["tilt_byte"]))
    assert abs(follow.recon.angles_at(2.0)[0] - ref.recon.angles_at(2.0)[0]) > 0.5
    # replay rebuilds the same dead reckoning from the recording (its `written` flags)
    res = replay_recording(rec)
    assert res.comparison["commands_equal"] and res.comparison["detections_equal"], res.comparison
    t_settled = max(c["send_t_s"] for c in cmds) + 2.0
    assert res.final_pose_deg == pytest.approx(ref.recon.angles_at(t_settled)[:2], abs=1e-9)


def test_all_writes_fine_changes_nothing(tmp_path):
    d, rec = _run(tmp_path, set())
    cmds = [c for c in RecordingReader(rec).records("commands") if c["source"] == "tracker"]
    assert all(c["written"] for c in cmds)
    ref = _written_only(d, cmds)
    for t in np.linspace(0.0, 2.5, 26):
        assert d.tracker.recon.angles_at(t) == ref.recon.angles_at(t)
