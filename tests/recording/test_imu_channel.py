"""The /imu channel: the IMU samples fed to the tracker, one protobuf ``foveatrack.ImuSamples`` message
a frame (foveatrack/recording/format.py).  Checked against the protobuf library itself (the schema
we hand-encode is the one it serialises; a message it encodes is one we decode and the reverse), read
back to the bit, the same bytes from the writer process as from the loop's thread."""

import numpy as np
import pytest

from foveatrack.recording import RecordingReader, RecordingWriter
from foveatrack.recording.format import (IMU, IMU_COLUMNS, IMU_DESCRIPTOR, IMU_SCHEMA_NAME, decode_imu_pb,
                                         encode_imu_pb, imu_columns)
from foveatrack.recording.writer_process import RecordingProcess

META = {"seed": 3}


def batches(seed=0):
    """Frames with the IMU batches a driver may feed: ~20 samples (some before the run: t < 0), one
    with accel, one empty (a frame whose samples had not come)."""
    rng = np.random.default_rng(seed)
    for k in range(6):
        t_ns = 1_000_000_000 + k * 100_000_000
        n = 0 if k == 4 else 20 + k
        t_s = np.sort(rng.uniform(-0.5, 0.1, n)) + k * 0.1
        gyro = rng.normal(0, 0.3, (n, 3))
        accel = rng.normal(0, 1, (n, 3)) if k == 2 else None
        yield k, t_ns, t_s, gyro, accel


def write_all(w):
    for k, t_ns, t_s, gyro, accel in batches():
        w.write_points(t_ns, k, np.zeros((3, 3)), np.full(3, t_ns), np.zeros(3, np.uint8))
        w.write_imu(t_ns, k, t_s, gyro, accel)
        w.write_detection(t_ns, k, False)


def test_batches_read_back_to_the_bit_and_the_child_writes_the_same_bytes(tmp_path):
    with RecordingWriter(tmp_path / "thread.mcap", META, created_utc="fixed") as w:
        write_all(w)
        assert w.messages_written == 18
    with RecordingProcess().open(tmp_path / "process.mcap", META, created_utc="fixed") as w:
        write_all(w)
        assert (w.frames_written, w.messages_written) == (6, 18)
    assert (tmp_path / "process.mcap").read_bytes() == (tmp_path / "thread.mcap").read_bytes()
    r = RecordingReader(tmp_path / "thread.mcap")
    got = list(r.imu())
    assert r.channels()[IMU] == 6 and r.problem is None
    for b, (k, t_ns, t_s, gyro, accel) in zip(got, batches(), strict=True):
        assert (b.t_ns, b.frame_id, len(b)) == (t_ns, k, len(t_s))
        assert b.t_s.tobytes() == t_s.tobytes() and b.gyro_rad_s.tobytes() == gyro.tobytes()
        assert (b.accel_g is None) == (accel is None or len(t_s) == 0)
        if b.accel_g is not None:
            assert b.accel_g.tobytes() == accel.tobytes()
    # in file order each batch comes right after the points of the frame it precedes
    order = [m.channel for m in r.messages() if m.channel in ("points", IMU)]
    assert order == ["points", IMU] * 6


def test_the_hand_encoded_schema_is_what_protobuf_serialises():
    from google.protobuf import descriptor_pb2

    want = descriptor_pb2.FileDescriptorSet()
    f = want.file.add(name="foveatrack/ImuSamples.proto", package="foveatrack", syntax="proto3")
    m = f.message_type.add(name="ImuSamples")
    F = descriptor_pb2.FieldDescriptorProto
    m.field.add(name="t_ns", number=1, label=F.LABEL_OPTIONAL, type=F.TYPE_UINT64, json_name="tNs")
    m.field.add(name="frame_id", number=2, label=F.LABEL_OPTIONAL, type=F.TYPE_INT64, json_name="frameId")
    for i, name in enumerate(IMU_COLUMNS):
        json_name = name.split("_")[0] + "".join(w.capitalize() for w in name.split("_")[1:])
        m.field.add(name=name, number=3 + i, label=F.LABEL_REPEATED, type=F.TYPE_DOUBLE, json_name=json_name)
    assert want.SerializeToString() == IMU_DESCRIPTOR
    assert f"{f.package}.{m.name}" == IMU_SCHEMA_NAME


def _protobuf_class():
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    pool = descriptor_pool.DescriptorPool()
    for fd in descriptor_pb2.FileDescriptorSet.FromString(IMU_DESCRIPTOR).file:
        pool.Add(fd)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(IMU_SCHEMA_NAME))


@pytest.mark.parametrize("with_accel", [False, True])
def test_our_messages_and_protobufs_are_the_same_bytes(with_accel):
    rng = np.random.default_rng(5)
    t, g, a = imu_columns(np.arange(19) / 200 - 3.0, rng.normal(0, 1, (19, 3)),
                          rng.normal(0, 1, (19, 3)) if with_accel else None)
    ours = encode_imu_pb(1_234_567_891, 17, t, g, a)
    msg = _protobuf_class().FromString(ours)
    assert (msg.t_ns, msg.frame_id) == (1_234_567_891, 17)
    assert np.array(msg.t_s).tobytes() == t.tobytes()
    assert np.stack([msg.gyro_x_rad_s, msg.gyro_y_rad_s, msg.gyro_z_rad_s], 1).tobytes() == g.tobytes()
    assert len(msg.accel_x_g) == (19 if with_accel else 0)
    assert msg.SerializeToString() == ours      # proto3 packs repeated doubles, in field order
    back = decode_imu_pb(msg.SerializeToString())
    assert back.t_s.tobytes() == t.tobytes() and back.gyro_rad_s.tobytes() == g.tobytes()
    assert (back.accel_g is None) != with_accel


def test_a_negative_frame_id_and_unpacked_doubles_decode():
    # a protobuf encoder may write a repeated double unpacked (one field per value): readers must take both
    cls = _protobuf_class()
    msg = cls(t_ns=5, frame_id=-3, t_s=[0.5, 0.6], gyro_x_rad_s=[1, 2], gyro_y_rad_s=[3, 4], gyro_z_rad_s=[5, 6])
    b = decode_imu_pb(msg.SerializeToString())
    assert b.frame_id == -3 and b.gyro_rad_s.tolist() == [[1, 3, 5], [2, 4, 6]]
    unpacked = b"\x08\x05" + b"".join(bytes([3 << 3 | 1]) + np.float64(v).tobytes() for v in (0.5, 0.6)) + \
        b"".join(bytes([(4 + i) << 3 | 1]) + np.float64(v).tobytes() for i in range(3) for v in (i, i + 0.5))
    b = decode_imu_pb(unpacked)
    assert b.t_s.tolist() == [0.5, 0.6] and b.gyro_rad_s.tolist() == [[0, 1, 2], [0.5, 1.5, 2.5]]


def test_wrong_shapes_and_channel_are_errors(tmp_path):
    with RecordingWriter(tmp_path / "r.mcap", META) as w:
        with pytest.raises(ValueError, match="3 IMU sample times but 2 gyro samples"):
            w.write_imu(1, 0, [0.1, 0.2, 0.3], np.zeros((2, 3)))
        with pytest.raises(ValueError, match="1 IMU sample times but 1 gyro samples and 2 accel samples"):
            w.write_imu(1, 0, [0.1], np.zeros((1, 3)), np.zeros((2, 3)))
        with pytest.raises(ValueError, match="use write_imu"):
            w.write(IMU, 1, {"t_s": []})
    with RecordingProcess() as p:
        p.open(tmp_path / "p.mcap", META)
        with pytest.raises(ValueError, match="2 IMU sample times but 1 gyro"):
            p.write_imu(1, 0, [0.1, 0.2], np.zeros((1, 3)))


def test_a_damaged_imu_message_is_a_clear_error():
    # (the reader turns a ValueError of a message's decoding into a UserError naming the file)
    ok = encode_imu_pb(10, 0, *imu_columns([0.25, 0.5], np.full((2, 3), 0.125)))
    i = ok.find(np.array([0.25, 0.5]).tobytes())
    bad = ok[:i - 1] + bytes([ok[i - 1] - 1]) + ok[i:]       # the t_s column one byte short
    with pytest.raises(ValueError, match="an IMU column of 15 bytes is not a whole number of doubles"):
        decode_imu_pb(bad)
    short = encode_imu_pb(10, 0, *imu_columns([0.25, 0.5], np.full((2, 3), 0.125)))[:i + 16]   # gyro cut off
    with pytest.raises(ValueError, match=r"different lengths \(2, 0, 0, 0"):
        decode_imu_pb(short)


def test_a_recording_with_imu_batches_streams_to_the_live_view(tmp_path):
    # replay --live re-logs every message: the batches go back through write_imu (no client connected)
    from foveatrack.recording.live import stream_recording

    with RecordingWriter(tmp_path / "r.mcap", META) as w:
        write_all(w)
    assert stream_recording(tmp_path / "r.mcap", port=0, speed=1e6) == 18


def test_export_writes_every_sample_with_its_frame_and_refuses_a_recording_without_them(tmp_path, capsys):
    import csv

    from foveatrack.cli import main
    from foveatrack.errors import UserError
    from foveatrack.recording import export_imu, export_trajectory

    rec = tmp_path / "r.mcap"
    with RecordingWriter(rec, META, created_utc="fixed") as w:
        write_all(w)
    assert main(["export", str(rec), "--imu", str(tmp_path / "imu.npz")]) == 0
    assert "IMU samples ->" in capsys.readouterr().out
    z = np.load(tmp_path / "imu.npz")
    want = list(batches())
    assert z["t_s"].tobytes() == np.concatenate([b[2] for b in want]).tobytes()
    assert z["frame_index"].tolist() == [k for k, _, t_s, _, _ in want for _ in t_s]
    gyro = np.concatenate([b[3] for b in want])
    assert np.array_equal(np.stack([z[f"gyro_{a}_rad_s"] for a in "xyz"], axis=1), gyro)
    # accel only where the source gave it (frame 2); NaN elsewhere
    accel = np.stack([z[f"accel_{a}_g"] for a in "xyz"], axis=1)
    in_frame_2 = z["frame_index"] == 2
    assert np.array_equal(accel[in_frame_2], want[2][4]) and np.isnan(accel[~in_frame_2]).all()
    n = export_imu(rec, tmp_path / "imu.csv")
    with open(tmp_path / "imu.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert n == len(rows) == len(z["t_s"]) and float(rows[0]["t_s"]) == z["t_s"][0]
    assert rows[0]["accel_x_g"] == "" and rows[0]["gyro_x_rad_s"] != ""
    # asked of the record export, the channel is named with where to go instead of failing in a decoder
    with pytest.raises(UserError, match="'imu'.*export_imu"):
        export_trajectory(rec, tmp_path / "t.csv", channels=[IMU])
    bare = tmp_path / "bare.mcap"
    with RecordingWriter(bare, META, created_utc="fixed") as w:
        w.write_detection(1, 0, False)
    assert main(["export", str(bare), "--imu", str(tmp_path / "none.csv")]) == 2
    assert "holds no IMU samples" in capsys.readouterr().err
