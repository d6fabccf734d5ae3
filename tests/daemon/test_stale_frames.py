"""A frame processed too late steers nothing: the daemon sends STOP, records why, and replay repeats it.

Found in CI: at start-up on a loaded machine the daemon processed its first frames ~0.6 s late in a
burst while the sensor-to-host clock offset was still settling, so the first command was placed
0.34 s early in the dead reckoning and the world-frame tilt stayed ~0.9 deg off for the whole run.
Here the daemon runs in-process with a fake head link and a fake receiver whose clock offset we set.
"""

import time

from foveatrack.gate import STALE_FRAME
from foveatrack.recording import RecordingReader
from foveatrack.replay import replay_recording

from inprocess import inprocess_daemon, target_frame


class FakeHead:
    connected = True

    def __init__(self):
        self.frames = []

    def send_frame(self, raw):
        self.frames.append(raw)
        return True


def test_stale_frames_send_stop_and_replay_repeats_it(tmp_path):
    d, rec = inprocess_daemon(tmp_path, FakeHead())
    sent = []
    # A start-up burst: frames 0-5 are all processed at sensor time 0.75 s (0.65 ... 0.15 s late); from
    # frame 6 on, each is processed 10 ms after its end.
    for k in range(10):
        fr = target_frame(k)
        now_s = 0.75 if k < 6 else fr.t_end_s + 0.01
        d.rx.offset_s = time.monotonic() - now_s
        d._process(fr, time.monotonic())
        sent.append(d.head.client.frames[-1])
    d.recorder.close()
    # 0.65 ... 0.25 s late: stale; frame 5 (0.15 s late) is within the 0.2 s bound and steers
    assert d.counters["frames_stale"] == 5
    stop_bytes = bytes.fromhex("ff010000000001")
    assert sent[:5] == [stop_bytes] * 5
    assert all(s != stop_bytes for s in sent[5:]), [s.hex() for s in sent]   # then it pans toward the UAV
    cmds = [c for c in RecordingReader(rec).records("commands") if c["source"] == "tracker"]
    assert [STALE_FRAME in c.get("limited", ()) for c in cmds] == [True] * 5 + [False] * 5
    assert all(c["tracker_command"][0] == 1 for c in cmds[:5])       # what the tracker wanted: pan left
    # the dead reckoning knows the head stayed put until the first command that left (~0.75 s)
    assert d.tracker.recon.angles_at(0.75)[0] == 0.0 and d.tracker.recon.angles_at(1.1)[0] > 0.1
    res = replay_recording(rec)
    assert res.comparison["commands_equal"] and res.comparison["detections_equal"], res.comparison
    assert res.comparison["commands_compared"] == 10
