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
