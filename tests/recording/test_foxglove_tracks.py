"""The sky tracker's tracks in the Foxglove view (issue 28): every track of a /tracks record is drawn
on /scene with its id and label, where the record puts it, with its history as a line that grows (and
on /scene_keyframe, whole); a deleted track's entities are deleted and no later keyframe draws it.

Read back by peers that share nothing with our writer: the official ``mcap`` reader, the SceneUpdate
and Log protobuf classes of ``foxglove-schemas-protobuf`` (and the official protobuf decoder of
``mcap-protobuf-support`` for every protobuf message), the records as the JSON bytes on /tracks."""

from __future__ import annotations

import json
import sys
from collections import defaultdict
from pathlib import Path

import pytest
from foxglove_schemas_protobuf.Log_pb2 import Log
from foxglove_schemas_protobuf.SceneEntityDeletion_pb2 import SceneEntityDeletion
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from foveatrack.recording.format import IMU_SCHEMA_NAME, OPTIONAL_RECORD_SCHEMAS, RECORD_SCHEMAS

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from foxglove_json_schema import parse_json_schema  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
MATCHING_ID = SceneEntityDeletion.MATCHING_ID


@pytest.fixture(scope="module")
def crossing(tmp_path_factory):
    """6 s of two-drones-crossing as ``simulate --out`` records it (the writer process draws the view):
    both drones confirmed, the fovea turned between them."""
    from foveatrack.cli import main

    out = tmp_path_factory.mktemp("crossing") / "run"
    assert main(["simulate", str(ROOT / "scenes" / "two-drones-crossing.toml"), "--duration", "6",
                 "--out", str(out), "--no-progress"]) == 0
    return read_view(out / "run.mcap")


@pytest.fixture(scope="module")
def swarm(tmp_path_factory):
    """6 s of swarm-of-five as ``simulate --out`` records it, tracking objects only (``lone_returns =
    false``): tracks deleted at 2.6 and 5.1 s (5.1 s: a keyframe time).  With single returns as hits
    (the default since 2026-12-07) the swarm's tracks live through these 6 s, and the crossing, whose
    warm-up is now tracked at its end, deletes none in its first 6 s either."""
    from foveatrack.cli import main

    base = tmp_path_factory.mktemp("swarm")
    text = (ROOT / "scenes" / "swarm-of-five.toml").read_text()
    assert text.rstrip().endswith("[tracker.sky]")
    scene = base / "swarm-objects-only.toml"
    scene.write_text(text + "\nlone_returns = false\n")
    out = base / "run"
    assert main(["simulate", str(scene), "--duration", "6", "--out", str(out), "--no-progress"]) == 0
    return read_view(out / "run.mcap")


def read_view(path):
    """(the /tracks records, the /scene messages that draw tracks, every /scene_keyframe, the /log
    texts), each with its log time, decoded by the official reader and Foxglove's protobuf classes."""
    tracks, scene, keys, logs = [], [], [], []
    with open(path, "rb") as fh:
        for _schema, ch, m in make_reader(fh).iter_messages(
                topics=["/tracks", "/scene", "/scene_keyframe", "/log"]):
            if ch.topic == "/tracks":
                tracks.append((m.log_time, json.loads(m.data)))
            elif ch.topic == "/log":
                logs.append(Log.FromString(m.data).message)
            else:
                u = SceneUpdate.FromString(m.data)
                if ch.topic == "/scene_keyframe":
                    keys.append((m.log_time, u))
                elif u.deletions or any(e.id.startswith("track_") for e in u.entities):
                    scene.append((m.log_time, u))
    return {"path": path, "tracks": tracks, "scene": scene, "keys": keys, "logs": logs}


def xyz(v):
    return [v.x, v.y, v.z]


def expected_text(rec, t):
    words = ([] if t["confirmed"] else ["tentative"]) + [w for k, w in (
        ("fixated", "fovea"), ("next_target", "next"), ("pinned", "pinned"))
        if rec[k] == t["id"] and not (k == "next_target" and rec["fixated"] == t["id"])]
    return f"{t['id']} {t['label']}" + (f" ({', '.join(words)})" if words else "")


def test_every_track_is_drawn_where_its_record_puts_it_with_its_id_and_label(crossing):
    scene = dict(crossing["scene"])
    assert len(scene) == len(crossing["scene"]), "one /scene message of tracks a frame"
    confirmed, drawn_frames = set(), 0
    for t_log, rec in crossing["tracks"]:
        if not rec["tracks"]:
            assert t_log not in scene or not scene[t_log].entities
            continue
        ents = {e.id: e for e in scene[t_log].entities}
        drawn_frames += 1
        for t in rec["tracks"]:
            e = ents[f"track_{t['id']}/marker"]
            assert e.frame_id == "world"
            (sphere,), (text,) = e.spheres, e.texts
            assert xyz(sphere.pose.position) == t["xyz_m"]        # float64 both ways: to the bit
            assert text.text == expected_text(rec, t) and text.text.startswith(f"{t['id']} {t['label']}")
            assert text.billboard and xyz(text.pose.position)[:2] == t["xyz_m"][:2]
            assert sphere.size.x == (0.8 if t["confirmed"] else 0.5)
            assert (sphere.color.a == 0.6) == t["confirmed"]       # tentative: paler
            meta = {kv.key: kv.value for kv in e.metadata}
            assert meta["label"] == t["label"] and meta["confirmed"] == str(t["confirmed"]).lower()
            if t["confirmed"]:
                confirmed.add(t["id"])
        # nothing else: a marker and the current path segment per live track
        assert {i.rsplit("/", 1)[0] if "/path/" in i else i for i in ents} == {
            f"track_{t['id']}/{k}" for t in rec["tracks"] for k in ("marker", "path")}
    assert drawn_frames >= 40 and len(confirmed) >= 2, "both drones confirmed within 6 s"
    # one text names the fixated track with "fovea" whenever the fovea serves one
    fov = [(t_log, rec["fixated"]) for t_log, rec in crossing["tracks"] if rec["fixated"] is not None]
    assert fov
    for t_log, tid in fov:
        assert "fovea" in {e.id: e for e in scene[t_log].entities}[f"track_{tid}/marker"].texts[0].text


def test_each_tracks_history_grows_and_is_the_positions_it_was_recorded_at(crossing):
    positions = defaultdict(list)                 # id -> [(log time, xyz)] as recorded
    for t_log, rec in crossing["tracks"]:
        for t in rec["tracks"]:
            positions[t["id"]].append((t_log, t["xyz_m"]))
    segments = defaultdict(dict)                  # id -> segment number -> its newest points
    lengths = defaultdict(list)
    for _t, u in crossing["scene"]:
        for e in u.entities:
            if "/path/" in e.id:
                tid, seg = int(e.id.split("/")[0][len("track_"):]), int(e.id.rsplit("/", 1)[1])
                pts = [xyz(p) for ln in e.lines for p in ln.points]
                segments[tid][seg] = pts
                lengths[tid].append(sum(len(s) for s in segments[tid].values()))
    for tid, pos in positions.items():
        # the segments, each starting at the last point of the one before, are the track's path
        segs = [segments[tid][k] for k in sorted(segments[tid])]
        line = segs[0] + [p for s in segs[1:] for p in s[1:]]
        assert line == [p for _t, p in pos], tid
        assert lengths[tid] == sorted(lengths[tid]), "the drawn line only grows"
    # the keyframes: each live track's whole history so far, one line, longer each second
    hist = defaultdict(list)
    for t_key, u in crossing["keys"]:
        assert "space_of_interest" in {e.id for e in u.entities}
        for e in u.entities:
            if e.id.startswith("track_"):
                assert e.id.endswith("/path/history")
                tid = int(e.id.split("/")[0][len("track_"):])
                pts = [xyz(p) for ln in e.lines for p in ln.points]
                before = [p for t, p in positions[tid] if t < t_key]
                upto = [p for t, p in positions[tid] if t <= t_key]
                assert pts in (before, upto) or (len(before) < 2 and not pts)
                hist[tid].append(len(pts))
    long_lived = [tid for tid, n in hist.items() if len(n) >= 3]
    assert long_lived
    for tid in long_lived:
        assert hist[tid] == sorted(hist[tid]) and hist[tid][-1] > hist[tid][0] >= 0


def test_a_deleted_tracks_entities_are_deleted_and_no_later_keyframe_draws_it(swarm):
    deleted = [(t_log, tid) for t_log, rec in swarm["tracks"] for tid in rec["deleted_now"]]
    assert deleted, "the swarm's tracks 2 and 0 are deleted at 2.6 and 5.1 s"
    scene = dict(swarm["scene"])
    for t_del, tid in deleted:
        prefix = f"track_{tid}/"
        sent = {e.id for t, u in swarm["scene"] if t < t_del for e in u.entities if e.id.startswith(prefix)}
        assert f"{prefix}marker" in sent and any("/path/" in i for i in sent)
        dels = [d for d in scene[t_del].deletions if d.id.startswith(prefix)]
        assert {d.id for d in dels} == sent and all(d.type == MATCHING_ID for d in dels)
        # never drawn again on /scene, nor on /scene_keyframe
        assert not [e.id for t, u in swarm["scene"] if t >= t_del for e in u.entities if e.id.startswith(prefix)]
        # a keyframe of the head estimate at the deletion's own time comes before that frame's tracks
        # record (it still draws the track); the keyframe that deletes it follows and supersedes it
        at_del = [i for i, (t, u) in enumerate(swarm["keys"])
                  if t == t_del and any(d.id.startswith(prefix) for d in u.deletions)]
        later = [u for i, (t, u) in enumerate(swarm["keys"]) if t >= t_del and (not at_del or i > at_del[0])]
        assert (at_del or later) and all(not e.id.startswith(prefix) for u in later for e in u.entities)
        drawn_by_a_keyframe = any(e.id == f"{prefix}path/history" for t, u in swarm["keys"] if t < t_del
                                  for e in u.entities)
        if drawn_by_a_keyframe:
            # a whole keyframe at the deletion removes it (a seek restores only the newest keyframe: D
            # and the other histories are in it too)
            (now,) = [u for t, u in swarm["keys"] if t == t_del and u.deletions]
            assert [(d.id, d.type) for d in now.deletions] == [(f"{prefix}path/history", MATCHING_ID)]
            prev = [u for t, u in swarm["keys"] if t < t_del][-1]
            assert {e.id for e in prev.entities} - {f"{prefix}path/history"} <= {e.id for e in now.entities}
    for _t, tid in deleted:
        assert sum(f"track {tid} deleted" in s for s in swarm["logs"]) == 1, tid


def test_the_log_has_the_track_events_not_every_record(crossing):
    logs = crossing["logs"]
    confirmed = [tid for _t, rec in crossing["tracks"] for tid in rec["confirmed_now"]]
    for tid in confirmed:
        assert sum(s.startswith(f"track {tid} confirmed") for s in logs) == 1
    drones = {t["id"] for _t, rec in crossing["tracks"] for t in rec["tracks"] if t["label"] == "drone"}
    assert drones and all(any(s.startswith(f"track {tid} is now drone") for s in logs) for tid in drones), drones
    assert not [s for s in logs if '"tracks"' in s], "before: the whole /tracks record, every frame"
    assert len(logs) < len(crossing["tracks"])


def test_every_channel_of_a_sky_recording_is_well_known_or_documented_and_decodes(crossing):
    with open(crossing["path"], "rb") as fh:
        r = make_reader(fh, decoder_factories=[DecoderFactory()])
        summary = r.get_summary()
        n = sum(1 for _ in r.iter_decoded_messages(topics=[
            c.topic for c in summary.channels.values() if c.message_encoding == "protobuf"]))
    documented = {name: s for name, s in list(RECORD_SCHEMAS.values()) + list(OPTIONAL_RECORD_SCHEMAS.values())}
    topics = set()
    for ch in summary.channels.values():
        sc = summary.schemas[ch.schema_id]
        topics.add(ch.topic)
        if ch.message_encoding == "json":
            assert sc.name in documented and json.loads(sc.data) == documented[sc.name], ch.topic
            parse_json_schema(json.loads(sc.data), sc.name)      # Foxglove's plot panel accepts it
        else:
            assert sc.name.startswith("foxglove.") or sc.name == IMU_SCHEMA_NAME, ch.topic
    assert {"/tracks", "/truth_objects", "/scene", "/scene_keyframe"} <= topics
    assert n == sum(summary.statistics.channel_message_counts[c.id] for c in summary.channels.values()
                    if c.message_encoding == "protobuf")


def test_a_confirmed_track_deleted_after_a_keyframe_the_pin_and_a_track_without_a_position(tmp_path):
    # written record by record (no simulation): track 7 a confirmed drone, pinned and fixated, deleted
    # at frame 15 after the keyframes at frames 0 and 10; track 9 tentative, the next target, without a
    # position at frame 5; a record the view cannot read at frame 3 is recorded and draws nothing
    from foveatrack.recording.writer import RecordingWriter

    path = tmp_path / "sky.mcap"
    with RecordingWriter(path, {}) as w:
        for k in range(25):
            t = (k + 1) * 100_000_000
            w.write_head_estimate(t, 0.0, 0.0, frame_id=k)
            tr = []
            if k < 15:
                tr.append({"id": 7, "confirmed": True, "label": "drone", "looks_like": "drone",
                           "xyz_m": [20.0 + k, 1.0, 3.0], "velocity_m_s": [10.0, 0.0, 0.0], "hit": True,
                           "in_view": True, "score": 0.9})
            tr.append({"id": 9, "confirmed": False, "label": "unknown", "looks_like": "bird",
                       "xyz_m": None if k == 5 else [30.0, -2.0, 4.0 + 0.1 * k], "velocity_m_s": None,
                       "hit": True, "in_view": True, "score": None})
            rec = {"frame_id": k, "fixated": 7 if k < 15 else None, "next_target": 9, "pinned": 7 if k < 15 else None,
                   "in_fovea": [], "n_points": 100, "n_foreground": 10, "n_objects": len(tr),
                   "confirmed_now": [7] if k == 0 else [], "deleted_now": [7] if k == 15 else [], "tracks": tr}
            w.write("tracks", t, {"frame_id": k, "tracks": "garbled"} if k == 3 else rec)
    v = read_view(path)
    by_t = dict(v["scene"])
    assert len(v["tracks"]) == 25 and sorted(by_t) == [(k + 1) * 100_000_000 for k in range(25) if k != 3]
    first = {e.id: e for e in by_t[100_000_000].entities}
    assert first["track_7/marker"].texts[0].text == "7 drone (fovea, pinned)"
    assert first["track_9/marker"].texts[0].text == "9 unknown (tentative, next)"
    c7, c9 = first["track_7/marker"].spheres[0].color, first["track_9/marker"].spheres[0].color
    assert (c7.r, c7.g, c7.b) == pytest.approx((0.1, 0.9, 0.2)) and c9.a < c7.a and c9.r > 0.4
    # no position at frame 5: track 9 is not drawn that frame and not deleted either
    f5 = by_t[600_000_000]
    assert "track_9/marker" not in {e.id for e in f5.entities} and not f5.deletions
    # frame 15: track 7's marker and both path segments deleted on /scene, its history on a keyframe
    f15 = by_t[1_600_000_000]
    assert [d.id for d in f15.deletions] == ["track_7/marker", "track_7/path/0", "track_7/path/1"]
    keys = [(t, {e.id for e in u.entities}, [d.id for d in u.deletions]) for t, u in v["keys"]]
    assert [(t, d) for t, _ids, d in keys] == [(100_000_000, []), (1_100_000_000, []),
                                               (1_600_000_000, ["track_7/path/history"]), (2_100_000_000, [])]
    assert "track_7/path/history" in keys[1][1]
    assert [ids for _t, ids, _d in keys[2:]] == [{"track_9/path/history"}] * 2
    assert "track 7 deleted (frame 15)" in v["logs"] and "track 7 confirmed (drone, frame 0)" in v["logs"]
