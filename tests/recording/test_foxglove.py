"""Recordings in Foxglove's schemas, read back by the official ``mcap`` reader with its protobuf
decoder (``mcap-protobuf-support``): a route to the file that shares nothing with our reader.

Checks: every channel is a Foxglove well-known schema in protobuf, one of the documented custom
JSON schemas (docs/recordings.md) or /imu's protobuf ``foveatrack.ImuSamples``; the transforms chain
world -> head_est -> lidar and give the head rotation of :func:`foveatrack.reconstruction.rotation_matrix` at the recorded estimate (and
world -> head_true the recorded truth); the PointCloud decoded by protobuf is the frame our reader
returns, to the bit, and so are the IMU samples of a gyro run; the channel table the writer predicts
names the ids the file's summary has.  Each check runs on fig12 and on its variant with the lidar's
IMU on the head and attitude = "gyro"."""

import json
import math
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from foveatrack.reconstruction import rotation_matrix
from foveatrack.recording import RecordingReader
from foveatrack.recording.foxglove_view import head_quaternion
from foveatrack.recording.format import CHANNELS_META_NAME, IMU_SCHEMA_NAME, RECORD_SCHEMAS

ROOT = Path(__file__).resolve().parents[2]
WELL_KNOWN = {"foxglove.PointCloud", "foxglove.FrameTransforms", "foxglove.SceneUpdate", "foxglove.Log"}


def _ran(path):
    """The tracker configuration a recording says ran (its typed metadata)."""
    from foveatrack.recording.run_meta import RecordingMeta

    return RecordingMeta.from_dict(RecordingReader(path).meta).tracker


@pytest.fixture(scope="module", params=["fig12", "fig12-gyro"])
def sim_rec(request, tmp_path_factory):
    """0.6 s of fig12-tracking (and of its gyro variant) recorded as ``simulate --out`` records it
    (from a child process, log times from the scene's start in UTC)."""
    from sim.attitude_study import scene_variant
    from sim.loop import ClosedLoop
    from sim.recorder import SimRecorder, recording_meta
    from sim.scene import load_scene, with_run_overrides

    path = tmp_path_factory.mktemp("fox") / "run.mcap"
    src = ROOT / "scenes" / "fig12-tracking.toml"
    scene = (scene_variant(src, "gyro", duration_s=0.6) if request.param == "fig12-gyro"
             else with_run_overrides(load_scene(src), 0.6, None))
    loop = ClosedLoop(scene)
    from foveatrack.recording.writer_process import RecordingProcess

    with RecordingProcess().open(path, recording_meta(scene, loop), log_time=scene.start_utc_ns) as w:
        loop.frame_hook = SimRecorder(w)
        log = loop.run()
    return path, log


def official_decoded(path, topics):
    """(log time, message) of ``topics``, each decoded by the official reader's protobuf decoder."""
    with open(path, "rb") as fh:
        return [(m.log_time, d) for _s, _c, m, d in
                make_reader(fh, decoder_factories=[DecoderFactory()]).iter_decoded_messages(topics=topics)]


def decoded(path):
    with open(path, "rb") as fh:
        r = make_reader(fh, decoder_factories=[DecoderFactory()])
        summary = r.get_summary()
        msgs = []
        for schema, channel, message in r.iter_messages():
            if channel.message_encoding == "json":
                msgs.append((channel.topic, message.log_time, json.loads(message.data), message.data))
            else:
                msgs.append((channel.topic, message.log_time, None, message.data))
        return summary, msgs


def quat_to_matrix(q):
    x, y, z, w = q.x, q.y, q.z, q.w
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def test_every_channel_is_well_known_or_documented(sim_rec):
    path, _ = sim_rec
    summary, _ = decoded(path)
    custom = {name for name, _schema in RECORD_SCHEMAS.values()}
    seen = set()
    for ch in summary.channels.values():
        sc = summary.schemas[ch.schema_id]
        seen.add(ch.topic)
        if sc.name in WELL_KNOWN or sc.name == IMU_SCHEMA_NAME:
            assert (ch.message_encoding, sc.encoding) == ("protobuf", "protobuf"), ch.topic
            assert (sc.name == IMU_SCHEMA_NAME) == (ch.topic == "/imu")
        else:
            assert sc.name in custom, (ch.topic, sc.name)
            assert (ch.message_encoding, sc.encoding) == ("json", "jsonschema"), ch.topic
            assert json.loads(sc.data)["title"] == sc.name
    assert {"/points", "/tf", "/scene", "/detections", "/head", "/commands", "/truth"} <= seen
    assert ("/imu" in seen) == (_ran(path).attitude == "gyro")
    # and every protobuf message decodes under its schema with the official decoder
    n = len(official_decoded(path, ["/points", "/tf", "/scene", "/scene_keyframe", "/log", "/imu"]))
    assert n == sum(summary.statistics.channel_message_counts[c.id] for c in summary.channels.values()
                    if c.message_encoding == "protobuf")


def test_transforms_chain_world_to_lidar_at_the_recorded_poses(sim_rec):
    path, log = sim_rec
    tfs = {}
    msgs = official_decoded(path, ["/tf"])
    for _log_time, dec in msgs:
        for t in dec.transforms:
            tfs[(t.timestamp.seconds * 10**9 + t.timestamp.nanos, t.child_frame_id)] = t
    rec = RecordingReader(path)
    heads = rec.records("head")
    truths = rec.records("truth")
    assert heads and len(truths) == len(heads)
    # one message a frame with both chains: a seek restores only the newest message of a topic, and
    # it alone resolves lidar and lidar_true (before: two messages a frame, the last the true chain)
    assert [t for t, _ in msgs] == [h["t_ns"] + 1767225600 * 10**9 for h in heads]
    for _t, dec in msgs:
        assert sorted(t.child_frame_id for t in dec.transforms) == ["head_est", "head_true", "lidar", "lidar_true"]
    for h, tr in zip(heads, truths):
        t = h["t_ns"]
        lidar = tfs[(t, "lidar")]
        assert lidar.parent_frame_id == "head_est"
        head = tfs[(t, lidar.parent_frame_id)]
        assert head.parent_frame_id == "world"                 # world -> head_est -> lidar
        np.testing.assert_allclose(quat_to_matrix(head.rotation), rotation_matrix(h["pan_deg"], h["tilt_deg"]),
                                   atol=1e-12)
        true_head = tfs[(t, "head_true")]
        assert true_head.parent_frame_id == "world" and tfs[(t, "lidar_true")].parent_frame_id == "head_true"
        np.testing.assert_allclose(quat_to_matrix(true_head.rotation),
                                   rotation_matrix(tr["pan_deg"], tr["tilt_deg"]), atol=1e-12)


def test_pointcloud_decoded_by_protobuf_is_the_frame_our_reader_returns(sim_rec):
    # Format 4: the simulator's points are on the Livox mm grid, so x, y, z travel as float32 metres
    # (Foxglove draws them within 0.25 mm of the point) from which rint(1000 v) gives the mm exactly;
    # the point times as int32 age_ns (frame time - point time), nothing outside the schema
    # (tests/recording/test_pointcloud_schema.py checks it with Foxglove's own class).
    from google.protobuf.unknown_fields import UnknownFieldSet

    path, log = sim_rec
    ours = list(RecordingReader(path).points())
    clouds = official_decoded(path, ["/points"])
    assert len(clouds) == len(ours) == len(log["t_end_s"])
    start = RecordingReader(path).info["log_time"]
    for f, (t, pc) in zip(ours, clouds):
        assert pc.frame_id == "lidar" and start == "t_ns+1767225600000000000" and t == f.t_ns + 1767225600 * 10**9
        # a pose, as the schema has it: identity, the points in frame lidar (before: none)
        assert pc.HasField("pose") and pc.pose.HasField("orientation") and pc.pose.orientation.w == 1.0
        assert (pc.pose.position.x, pc.pose.position.y, pc.pose.position.z) == (0.0, 0.0, 0.0)
        assert pc.timestamp.seconds * 10**9 + pc.timestamp.nanos == f.t_ns
        names = {fl.name: fl for fl in pc.fields}
        assert set(names) == {"x", "y", "z", "age_ns", "reflectivity"}
        dt = np.dtype({"names": ["x", "y", "z", "age_ns", "reflectivity"],
                       "formats": ["<f4", "<f4", "<f4", "<i4", "u1"],
                       "offsets": [names[n].offset for n in ("x", "y", "z", "age_ns", "reflectivity")],
                       "itemsize": pc.point_stride})
        assert pc.point_stride == 17
        arr = np.frombuffer(pc.data, dt)
        v = np.stack([arr["x"], arr["y"], arr["z"]], 1).astype(np.float64)
        assert np.abs(v - f.xyz).max() <= 0.25e-3                       # drawn where the point is
        assert np.array_equal(np.rint(v * 1000) * 1e-3, f.xyz)          # and exact through the mm
        assert list(UnknownFieldSet(pc)) == []
        assert arr["age_ns"].min() >= 0 and arr["age_ns"].max() <= 100_000_000    # the frame's 100 ms
        assert np.array_equal(f.t_ns - arr["age_ns"].astype(np.int64), f.t_ns_points)
        assert np.array_equal(arr["reflectivity"], f.reflectivity)
    assert [f.frame_index for f in ours] == list(range(len(ours)))


def test_imu_samples_decoded_by_protobuf_are_the_batches_our_reader_returns(sim_rec):
    # the gyro run: one message a frame, right after its points, with the head gyro's 20 samples of
    # the frame (the first also the 5 s at rest before it); the plain run records none
    path, log = sim_rec
    ours = list(RecordingReader(path).imu())
    theirs = official_decoded(path, ["/imu"])
    assert len(theirs) == len(ours)
    if not ours:
        assert _ran(path).attitude == "commands"
        return
    assert len(ours) == len(log["t_end_s"])
    assert [len(b) for b in ours] == [1000 + 20] + [20] * (len(ours) - 1)     # 200 Hz, rest_before_s 5
    for k, (b, (t, d)) in enumerate(zip(ours, theirs)):
        assert t - 1767225600 * 10**9 == b.t_ns == d.t_ns == round(log["t_end_s"][k] * 1e9)
        assert b.frame_id == d.frame_id == k
        assert np.array(d.t_s).tobytes() == b.t_s.tobytes()
        assert np.stack([d.gyro_x_rad_s, d.gyro_y_rad_s, d.gyro_z_rad_s], 1).tobytes() == b.gyro_rad_s.tobytes()
        assert len(d.accel_x_g) == 0 and b.accel_g is None      # the simulated head IMU has no accelerometer
        # the samples of the frame: from the previous frame's end (on the 5 ms grid) to before its own
        assert b.t_s[-1] < log["t_end_s"][k] and (k == 0 or round(b.t_s[0] * 1e9) == ours[k - 1].t_ns)


def test_the_channel_table_names_the_ids_of_the_summary(sim_rec):
    path, _ = sim_rec
    with open(path, "rb") as fh:
        r = make_reader(fh)
        table = {}
        for md in r.iter_metadata():
            if md.name == CHANNELS_META_NAME:
                table.update(json.loads(md.metadata["channels_json"]))
        summary = r.get_summary()
    assert table == {str(c.id): c.topic.lstrip("/") for c in summary.channels.values()}


@pytest.mark.parametrize("pan_deg,tilt_deg", [(0, 0), (30, 0), (0, 20), (-170, -35), (95.5, 61.2), (400, 10)])
def test_head_quaternion_is_the_trackers_rotation(pan_deg, tilt_deg):
    q = head_quaternion(pan_deg, tilt_deg)
    assert math.isclose(sum(v * v for v in q), 1.0, rel_tol=1e-12)

    class Q:
        x, y, z, w = q
    np.testing.assert_allclose(quat_to_matrix(Q), rotation_matrix(pan_deg, tilt_deg), atol=1e-12)


def test_a_simulator_recording_replays_to_the_bit(sim_rec):
    from foveatrack.replay import replay_recording

    path, log = sim_rec
    c = replay_recording(path).comparison
    assert c["detections_equal"] and c["commands_equal"] and c["max_detection_xyz_diff_m"] == 0.0
    assert c["commands_compared"] == len(log["t_end_s"])


def test_the_shipped_layout_names_channels_and_fields_a_recording_has(sim_rec):
    """docs/foxglove-layout.json (scripts/make_foxglove_layout.py): every plotted path is a field of
    its channel's schema, every topic it shows is one a simulator recording has."""
    path, _ = sim_rec
    doc = json.loads((ROOT / "docs" / "foxglove-layout.json").read_text())
    summary, _ = decoded(path)
    topics = {c.topic: json.loads(summary.schemas[c.schema_id].data) if c.message_encoding == "json" else None
              for c in summary.channels.values()}
    values, shown, table_paths = [], [], []

    def walk(x):
        if isinstance(x, dict):
            for k, v in x.items():
                if k == "value" and isinstance(v, str):
                    values.append(v)
                elif k == "topicToRender":
                    shown.append(v)
                elif k == "topicPath" and isinstance(v, str):
                    table_paths.append(v)
                elif k == "topics" and isinstance(v, dict):
                    shown.extend(v)
                walk(v)
        elif isinstance(x, list):
            for v in x:
                walk(v)
    walk(doc)
    assert len(values) >= 6 and {"/points", "/scene", "/log"} <= set(shown)
    assert set(shown) <= set(topics)
    for v in values:
        topic, field = v.split(".", 1)
        assert topic in topics and field in topics[topic]["properties"], v
    # a table of a channel only some recordings have (/tracks: a [tracker.sky] run): its documented schema
    from foveatrack.recording.format import OPTIONAL_RECORD_SCHEMAS

    assert table_paths == ["/tracks.tracks"]
    for v in table_paths:
        topic, field = v.split(".", 1)
        assert field in OPTIONAL_RECORD_SCHEMAS[topic.lstrip("/")][1]["properties"], v


def test_a_seek_or_a_late_viewer_gets_d_and_the_whole_history_within_a_second(tmp_path):
    # before: D was sent once at 0.1 s and the trajectories in 10-frame segments on /scene, so a
    # viewer who joined later, or a seek (which restores the newest message of each topic), lost them
    from sim.loop import ClosedLoop
    from sim.recorder import SimRecorder, recording_meta
    from sim.scene import load_scene, with_run_overrides

    from foveatrack.recording.writer import RecordingWriter

    scene = with_run_overrides(load_scene(ROOT / "scenes" / "fig12-tracking.toml"), 2.5, None)
    loop = ClosedLoop(scene)
    path = tmp_path / "run.mcap"
    with RecordingWriter(path, recording_meta(scene, loop)) as w:
        loop.frame_hook = SimRecorder(w)
        loop.run()
    key = official_decoded(path, ["/scene_keyframe"])
    heads = [t for t, _ in official_decoded(path, ["/tf"])]
    assert len(key) >= 2 and heads
    gaps = np.diff([heads[0], *[t for t, _ in key], heads[-1]])
    assert gaps.max() <= 1.0e9 + 1, "a keyframe at least once a second"
    assert _ran(path).space is not None
    for _t, msg in key:
        assert "space_of_interest" in {e.id for e in msg.entities}
    # the newest keyframe's trajectories reach back to the run's first truth and detection
    last = {e.id: e for e in key[-1][1].entities}
    first = RecordingReader(path).records("truth")[0]["target_xyz_m"]
    line = last["true_trajectory/history"].lines[0].points
    assert (line[0].x, line[0].y, line[0].z) == tuple(first)
    assert len(line) >= 19          # every truth until the keyframe at 2.0 s (fewer than HISTORY_POINTS)
    assert len(last["reconstructed_trajectory/history"].lines[0].points) >= 2


def test_a_long_history_is_thinned_evenly_and_keeps_its_start():
    from foveatrack.recording.foxglove_view import HISTORY_POINTS, FoxgloveChannels

    view = FoxgloveChannels({})
    for i in range(10 * HISTORY_POINTS + 3):
        view._remember("p", (float(i), 0.0, 0.0), (1.0, 1.0, 1.0))
    stride, pts = view._history["p"]
    xs = [p[0] for p in pts]
    assert len(pts) <= HISTORY_POINTS and xs[0] == 0.0
    assert set(np.diff(xs)) == {float(stride)}
    assert xs[-1] > 10 * HISTORY_POINTS - stride - 1


def test_one_tf_message_a_frame_without_truth_is_at_most_one_frame_late(tmp_path):
    # the daemon writes no truth: the first frame's transforms wait until the next frame's points
    # (a frame without truth), every later frame's go out with its head estimate, the last on close
    from foveatrack.recording.writer import RecordingWriter

    path = tmp_path / "daemon-like.mcap"
    with RecordingWriter(path, {}) as w:
        for k in range(4):
            t = (k + 1) * 100_000_000
            w.write_points(t, k, np.zeros((1, 3)), np.array([t]))
            w.write_head_estimate(t, 10.0 * k, 1.0, frame_id=k)
    msgs = official_decoded(path, ["/tf"])
    assert [t for t, _ in msgs] == [(k + 1) * 100_000_000 for k in range(4)]
    for k, (_t, dec) in enumerate(msgs):
        assert [t.child_frame_id for t in dec.transforms] == ["head_est", "lidar"]
        rot = quat_to_matrix(dec.transforms[0].rotation)
        np.testing.assert_allclose(rot, rotation_matrix(10.0 * k, 1.0), atol=1e-12)


def test_the_live_view_gets_each_frames_tf_before_the_next_frame_ends():
    # what a viewer of `daemon --live` sees: the first frame's /tf with the second frame's points,
    # every later one with its own head estimate
    from foveatrack.recording.format import packed_point_dtype
    from foveatrack.recording.foxglove_view import FoxgloveChannels

    view = FoxgloveChannels({})
    sent = []
    view._log_tf = lambda t_ns, tfs: sent.append((t_ns, len(tfs)))     # the SDK's messages hide their fields
    packed = np.zeros(0, packed_point_dtype("float32"))
    for k in range(3):
        t = (k + 1) * 100
        view.log_points(t, packed)
        assert [s[0] for s in sent] == [100 * (i + 1) for i in range(k)]      # frame 0 still waits at k = 0
        view.log_json("head", t, b"{}", {"pan_deg": 1.0, "tilt_deg": 2.0})
        assert [s[0] for s in sent] == [100 * (i + 1) for i in range(k if k == 0 else k + 1)]
    view.finish()
    assert sent == [(100 * (i + 1), 2) for i in range(3)]       # world -> head_est -> lidar


def test_log_times_are_utc_from_the_scenes_start_and_records_keep_the_simulator_clock(tmp_path):
    # before: log time = virtual time (from 0.1 s), so Foxglove showed 1970-01-01
    import datetime as dt

    from sim.loop import ClosedLoop
    from sim.recorder import SimRecorder, recording_meta
    from sim.scene import load_scene, scene_from_mapping, with_run_overrides

    from foveatrack.recording.writer import RecordingWriter

    src = ROOT / "scenes" / "fig12-tracking.toml"
    default = load_scene(src)
    assert default.start_utc_ns == 1767225600 * 10**9         # 2026-01-01T00:00:00Z, documented
    import tomllib
    data = tomllib.loads(src.read_text())
    data["scene"]["start_utc"] = "2026-06-01T14:30:00+02:00"
    scene = with_run_overrides(scene_from_mapping(data, str(src)), 0.3, None)
    start = dt.datetime(2026, 6, 1, 12, 30, tzinfo=dt.timezone.utc)
    assert scene.start_utc_ns == int(start.timestamp()) * 10**9
    loop = ClosedLoop(scene)
    path = tmp_path / "run.mcap"
    with RecordingWriter(path, recording_meta(scene, loop), log_time=scene.start_utc_ns) as w:
        loop.frame_hook = SimRecorder(w)
        loop.run()
    with open(path, "rb") as fh:
        logs = [(c.topic, m.log_time, m.data) for _s, c, m in make_reader(fh).iter_messages()]
    assert all(dt.datetime.fromtimestamp(t / 1e9, dt.timezone.utc).date() == start.date() for _c, t, _d in logs)
    heads = [json.loads(d) for c, _t, d in logs if c == "/head"]
    assert heads and [t for c, t, _d in logs if c == "/head"] == [h["t_ns"] + scene.start_utc_ns for h in heads]
    assert heads[0]["t_ns"] < 10**9                            # the record keeps the simulator's clock
    ours = RecordingReader(path)
    assert [m.t_ns for m in ours.messages("head")] == [h["t_ns"] for h in heads]
    assert [f.t_ns for f in ours.points()] == [h["t_ns"] for h in heads]


@pytest.mark.parametrize("text", ["2026-01-01T00:00:00", "yesterday", "1960-01-01T00:00:00Z", 5])
def test_a_wrong_start_utc_is_named(text):
    import tomllib

    from sim.scene import scene_from_mapping

    from foveatrack.errors import UserError

    src = ROOT / "scenes" / "fig12-tracking.toml"
    data = tomllib.loads(src.read_text())
    data["scene"]["start_utc"] = text
    with pytest.raises(UserError, match=r"\[scene\] start_utc: .* e\.g\. \"2026-01-01T00:00:00Z\""):
        scene_from_mapping(data, str(src))
