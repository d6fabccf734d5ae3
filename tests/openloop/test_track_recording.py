"""``foveatrack track --record``: a Foxglove-native recording of the run, with the cloud, the track and
the D of every frame, read back by the project's reader and the official MCAP reader."""

from pathlib import Path

import numpy as np
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from foveatrack.cli import main
from foveatrack.openloop import track_source
from foveatrack.recording import RecordingReader
from foveatrack.sources import open_source

FIXTURE = Path(__file__).parent / "mmaud_seq1" / "livox_avia"


def test_record_holds_the_cloud_the_track_and_d(tmp_path, capsys):
    rec = tmp_path / "track.mcap"
    assert main(["track", str(FIXTURE), "--record", str(rec), "--json"]) == 0
    capsys.readouterr()
    frames = [fr for _, fr in open_source(FIXTURE)]
    outs = []
    res = track_source(open_source(FIXTURE), observer=lambda k, a, fr, out: outs.append(out))
    r = RecordingReader(rec)
    pts = list(r.points())
    assert len(pts) == len(frames)
    for p, fr in zip(pts, frames):
        np.testing.assert_array_equal(p.xyz, fr.xyz)       # the cloud as read, exactly
    dets = [m.record for m in r.messages() if m.channel == "detections"]
    assert [d["detected"] for d in dets] == res.frames["detected"].tolist()
    for d, xyz in zip(dets, res.frames["xyz_m"]):
        if d["detected"]:
            assert d["xyz_m"] == xyz.tolist()
    with open(rec, "rb") as fh:
        d_msgs = [d for _s, _c, _m, d in make_reader(fh, decoder_factories=[DecoderFactory()])
                  .iter_decoded_messages(topics=["/openloop_d"])]
    assert len(d_msgs) == len(frames)
    for msg, out in zip(d_msgs, outs):
        cubes = msg.entities[0].cubes
        if out.d_min_m is None:
            assert len(cubes) == 0
        else:
            c = cubes[0]
            centre = np.array([c.pose.position.x, c.pose.position.y, c.pose.position.z])
            np.testing.assert_allclose(centre, (out.d_min_m + out.d_max_m) / 2, rtol=0, atol=1e-12)
            assert c.size.x == out.d_max_m[0] - out.d_min_m[0]
    assert sum(len(m.entities[0].cubes) for m in d_msgs) >= 9
    # replay has no head loop to re-run in it, and says what to do instead (it said only "source
    # 'openloop' is not 'simulator' or 'daemon'", where track pointed to replay: a user's audit)
    assert main(["replay", str(rec)]) == 2
    err = capsys.readouterr().err
    assert "a recording `foveatrack track --record` made" in err and "run `foveatrack track` on its source" in err


def test_record_refuses_frames_longer_than_a_recorded_frame_holds(tmp_path, capsys):
    # before: below ~0.47 Hz the frame's end lay more than 2.1 s from its points and the run ended in a
    # traceback, "ValueError: point times must lie within ±2.1 s of the frame t_ns"
    rec = tmp_path / "track.mcap"
    assert main(["track", str(FIXTURE), "--rate-hz", "0.4", "--record", str(rec)]) == 2
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    assert err.startswith("foveatrack: error: --record") and "--rate-hz 0.4 lasts 2.5 s" in err, err
    assert "2.147 s" in err and "--rate-hz 0.466 or more" in err, err
    assert not rec.exists()
    # the limit is the format's, not a round number: 0.466 Hz (2.146 s frames) records every frame
    assert main(["track", str(FIXTURE), "--rate-hz", "0.466", "--record", str(rec), "--json"]) == 0
    capsys.readouterr()
    frames = [fr for _, fr in open_source(FIXTURE, rate_hz=0.466)]
    pts = list(RecordingReader(rec).points())
    assert len(pts) == len(frames)
    for p, fr in zip(pts, frames):
        np.testing.assert_array_equal(p.t_ns_points, fr.t_ns)


def test_a_frame_whose_points_lie_too_far_from_its_end_is_refused_in_words(tmp_path):
    # points with times of their own (a bag's) can reach back further than the frame's length
    from foveatrack.errors import UserError
    from foveatrack.frames import Frame
    from foveatrack.openloop.recording import TrackRecorder
    from foveatrack.openloop.tracker import OpenLoopConfig, OpenLoopTracker

    t0 = 1_717_243_800_000_000_000
    xyz = np.array([[10.0, 0.0, 1.0], [10.0, 0.1, 1.0]])
    ok = Frame(t0 * 1e-9, t0 * 1e-9 + 0.1, xyz, np.array([t0, t0 + 50_000_000]))
    far = Frame(t0 * 1e-9 + 0.1, t0 * 1e-9 + 0.2, xyz, np.array([t0 - 2_100_000_000, t0 + 150_000_000]))
    tracker = OpenLoopTracker(OpenLoopConfig())
    rec = tmp_path / "t.mcap"
    with TrackRecorder(rec, {"input": "x"}) as r:
        r(0, ok.t_end_s, ok, tracker.process(ok))
        try:
            r(1, far.t_end_s, far, tracker.process(far))
        except UserError as exc:
            err = str(exc)
        else:
            raise AssertionError("a frame reaching back 2.3 s was recorded")
    assert "frame 1" in err and "-2.300 s" in err and "±2.147 s" in err, err
    assert len(list(RecordingReader(rec).points())) == 1
