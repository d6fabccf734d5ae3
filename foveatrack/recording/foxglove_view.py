"""Foxglove's well-known schemas for a recording: the channels, their schemas, and what is drawn.

One :class:`FoxgloveChannels` per writer owns a ``foxglove.Context`` (the official Foxglove SDK,
``foxglove-sdk``); every sink bound to that context -- the MCAP file of
:class:`foveatrack.recording.RecordingWriter`, the WebSocket server of the live view
(:mod:`foveatrack.recording.live`) -- receives the same channels.  docs/recordings.md lists them.

Frames (``FrameTransforms`` on ``/tf``)::

    world -> head_est -> lidar          the tracker's dead-reckoned head pose, the lidar on it
    world -> head_true -> lidar_true    simulation only: the true head pose

so the cloud (frame ``lidar``) sits in the world where the tracker believes it is, and the drift of
the estimate shows as the offset between ``head_est`` and ``head_true``.  Both chains of a frame travel
in one ``/tf`` message (log time: the head estimate's), because a seek restores only the newest message
of a topic: the head estimate's transforms wait for the frame's truth, which the simulator writes after
it; once a frame has passed without a truth (the daemon, a replay of its recording) they are sent as
they come, so only the first frame of such a run waits, until the next frame's points.  Head coordinates are the
tracker's (:func:`foveatrack.reconstruction.rotation_matrix`): ``world = R_z(pan) R_y(-tilt)
(p_lidar + lidar_offset_m)``, X forward, Y left, Z up, pan + = left, tilt + = up.
"""

from __future__ import annotations

import functools
import json
import math

import numpy as np
from foxglove.messages import (Color, CubePrimitive, CylinderPrimitive, FrameTransform, FrameTransforms, KeyValuePair,
                               LinePrimitive, LinePrimitiveLineType, Log, LogLevel, Point3, Pose, Quaternion,
                               SceneEntity, SceneEntityDeletion, SceneEntityDeletionType, SceneUpdate, SpherePrimitive,
                               TextPrimitive, Timestamp, Vector3)

from foveatrack.recording.format import (COMMANDS, DETECTIONS, HEAD, IMU, IMU_DESCRIPTOR, IMU_SCHEMA_NAME, LOG,
                                         METRICS, POINTS, RECORD_SCHEMAS, SCENE, SCENE_KEYFRAME, TF, TRACKS, TRUTH,
                                         TRUTH_OBJECTS, encode_imu_pb, encode_points_pb, json_schema_of)
from foveatrack.recording.run_meta import recorded_tracker
from foveatrack.space_of_interest import Box, Cylinder

KEYFRAME_FRAMES = 10       # /scene_keyframe: D and the histories every 10th head estimate (once a second)
_CLASS_COLOURS = {"drone": (0.1, 0.9, 0.2), "bird": (0.9, 0.7, 0.1), "tree": (0.2, 0.5, 0.2),
                  "clutter": (0.7, 0.7, 0.7),     # the truth of each object (/truth_objects), by class
                  "unknown": (0.4, 0.7, 1.0)}     # and each track (/tracks), by label: not yet classified
TRACK_MARKER_M = (0.8, 0.5)    # a track's sphere [m]: confirmed, tentative (paler, see _track_look)
HISTORY_POINTS = 256       # a history longer than this is thinned to every 2nd point (deterministic)
SEGMENT_FRAMES = 10        # a drawn trajectory is one line entity per 10 frames: each frame re-sends
                           # its segment, so short segments keep the bytes and the CPU per frame small


def head_quaternion(pan_deg: float, tilt_deg: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of ``R_z(pan) R_y(-tilt)`` (head -> world), the rotation of
    :func:`foveatrack.reconstruction.rotation_matrix`; pan, tilt [deg], any finite value."""
    hz = math.radians(pan_deg) / 2.0
    hy = -math.radians(tilt_deg) / 2.0
    cz, sz, cy, sy = math.cos(hz), math.sin(hz), math.cos(hy), math.sin(hy)
    return (-sz * sy, cz * sy, cy * sz, cz * cy)


def log_clock(log_time: int | str):
    """t_ns -> MCAP log time [ns]: ``t_ns + log_time`` (an int), the host's UTC clock ("host"), or
    ``log_time(t_ns)`` (a callable: a recording rewritten with its messages' own log times,
    :mod:`foveatrack.daemon.recover`)."""
    if callable(log_time):
        return lambda t_ns: int(log_time(t_ns))
    if log_time == "host":
        import time

        return lambda _t_ns: time.time_ns()
    if isinstance(log_time, bool) or not isinstance(log_time, int) or log_time < 0:
        raise ValueError(f"log_time must be an offset >= 0 [ns] or 'host', got {log_time!r}")
    return lambda t_ns: int(t_ns) + log_time


@functools.lru_cache(maxsize=64)        # a handful of colours, each made once
def _colour(rgb: tuple, a: float):
    return Color(r=rgb[0], g=rgb[1], b=rgb[2], a=a)


def _ts(t_ns: int):
    return Timestamp(int(t_ns) // 1_000_000_000, int(t_ns) % 1_000_000_000)


class FoxgloveChannels:
    """The channels of a recording on one ``foxglove.Context``, and the visual messages derived from
    the records (transforms, scene entities, log lines).

    meta : the recording's meta (the tracker configuration that ran gives D and the lidar offset:
        :func:`foveatrack.recording.run_meta.recorded_tracker`)
    points_dtype : "float64" (exact) or "float32" (x, y, z of the packed points)
    log_time : the MCAP log time of a message of time ``t_ns`` (the sensor's or the simulator's clock,
        which the messages keep): an int, ``t_ns`` + that many ns (the simulator: its scene's start
        in UTC), or "host": the host's clock (UTC) when the message is logged (the daemon)
    """

    def __init__(self, meta: dict | None = None, points_dtype: str = "float64", log_time: int | str = 0):
        import foxglove
        from foxglove.channels import FrameTransformsChannel, LogChannel, SceneUpdateChannel

        self.context = foxglove.Context()
        self._lt = log_clock(log_time)
        ctx = self.context
        self.first_log_order: list[str] = []     # channel names in the order of their first message
        self._seen: set[str] = set()
        # the SDK's own foxglove.PointCloud schema, on a plain channel: the points are encoded as the
        # SDK encodes them, from a template made once per layout (format.encode_points_pb)
        probe = foxglove.channels.PointCloudChannel("/_schema_probe", context=ctx)
        pc_schema = probe.schema()
        probe.close()
        self._points = foxglove.Channel("/" + POINTS, schema=pc_schema, message_encoding="protobuf", context=ctx)
        self._points_dtype = points_dtype
        self._json: dict[str, object] = {}
        self._imu = None        # made at the first IMU batch: a run without one records what it always did
        for name in RECORD_SCHEMAS:
            self._json_channel(name)
        self._tf = FrameTransformsChannel("/" + TF, context=ctx)
        self._scene = SceneUpdateChannel("/" + SCENE, context=ctx)
        self._keyframe = SceneUpdateChannel("/" + SCENE_KEYFRAME, context=ctx)
        self._log = LogChannel("/" + LOG, context=ctx)
        # D and the lidar offset of the configuration that ran (the typed metadata, any form it was written in)
        tracker = recorded_tracker(meta)
        self.lidar_offset_m = (0.0, 0.0, 0.0) if tracker is None else tuple(tracker.lidar_offset_m)
        self._space = None if tracker is None else tracker.space
        self._paths: dict[str, tuple[int, list]] = {}     # name -> (segment number, its points)
        self._state: str | None = None
        self._history: dict[str, tuple[int, list]] = {}   # name -> (stride, every stride-th point)
        self._seen_points: dict[str, int] = {}
        self._path_colors: dict[str, tuple] = {}
        self._head_count = 0
        self._keyframed: set[str] = set()                  # the histories the last keyframe drew
        self._tracks_drawn: dict[int, str] = {}            # track id -> its label, while drawn (/tracks)
        self._pending_tf: tuple[int, list] | None = None   # the head estimate's transforms, awaiting the truth
        self._truth_expected: bool | None = None            # None: not known yet (the first frame)

    # ------------------------------------------------------------------ channels

    def _json_channel(self, name: str):
        import foxglove

        ch = self._json.get(name)
        if ch is None:
            schema_name, schema = json_schema_of(name)
            ch = foxglove.Channel("/" + name, schema=foxglove.Schema(
                name=schema_name, encoding="jsonschema", data=json.dumps(schema).encode()),
                message_encoding="json", context=self.context)
            self._json[name] = ch
        return ch

    def _note(self, name: str) -> None:
        if name not in self._seen:
            self._seen.add(name)
            self.first_log_order.append(name)

    # ------------------------------------------------------------------ records

    def log_points(self, t_ns: int, packed: np.ndarray) -> None:
        self.end_frame()
        self._note(POINTS)
        self._points.log(encode_points_pb(t_ns, packed), log_time=self._lt(t_ns))

    def log_imu(self, t_ns: int, frame_id: int, t_s: np.ndarray, gyro_rad_s: np.ndarray,
                accel_g: np.ndarray | None = None) -> None:
        """One frame's IMU samples (arrays as :func:`foveatrack.recording.format.imu_columns` gives them)."""
        import foxglove

        if self._imu is None:
            self._imu = foxglove.Channel("/" + IMU, schema=foxglove.Schema(
                name=IMU_SCHEMA_NAME, encoding="protobuf", data=IMU_DESCRIPTOR),
                message_encoding="protobuf", context=self.context)
        self._note(IMU)
        self._imu.log(encode_imu_pb(t_ns, frame_id, t_s, gyro_rad_s, accel_g), log_time=self._lt(t_ns))

    def log_json(self, name: str, t_ns: int, payload: bytes, rec: dict) -> None:
        self._note(name)
        self._json_channel(name).log(payload, log_time=self._lt(t_ns))
        try:
            self._derive(name, int(t_ns), rec)
        except (KeyError, TypeError, ValueError, IndexError):
            pass    # a record without what a drawing needs (a caller's own fields) is recorded, not drawn

    # ------------------------------------------------------------------ what is drawn

    def _derive(self, name: str, t_ns: int, rec: dict) -> None:
        """Transforms, scene entities and log lines from a record just written."""
        if name == HEAD and rec.get("pan_deg") is not None:
            self.end_frame()
            tfs = self._head_tf(t_ns, "head_est", "lidar", rec["pan_deg"], rec["tilt_deg"])
            if self._truth_expected is False:
                self._log_tf(t_ns, tfs)
            else:
                self._pending_tf = (t_ns, tfs)
            # D is on /scene_keyframe (the first at this very head estimate), not sent here again
            if rec.get("world_xyz_m") is not None:
                self._scene_update(t_ns, [self._path_point("reconstructed_trajectory", t_ns, rec["world_xyz_m"],
                                                           (0.1, 0.5, 1.0))])
            if self._head_count % KEYFRAME_FRAMES == 0:
                self._scene_keyframe(t_ns)
            self._head_count += 1
        elif name == TRUTH and rec.get("pan_deg") is not None:
            self._truth_expected = True
            tfs = self._head_tf(t_ns, "head_true", "lidar_true", rec["pan_deg"], rec["tilt_deg"])
            if self._pending_tf is not None:
                (t_ns_head, est), self._pending_tf = self._pending_tf, None
                self._log_tf(t_ns_head, est + tfs)
            else:
                self._log_tf(t_ns, tfs)
            xyz = rec.get("target_xyz_m")
            if xyz is not None:
                self._scene_update(t_ns, [self._sphere("true_uav", t_ns, "world", xyz, 0.5, (0.1, 0.9, 0.2)),
                                          self._path_point("true_trajectory", t_ns, xyz, (0.1, 0.9, 0.2))])
        elif name == DETECTIONS:
            xyz = rec.get("xyz_m") if rec.get("detected") else None
            ent = self._sphere("detection", t_ns, "lidar", xyz, 0.6, (1.0, 0.2, 0.1))
            self._scene_update(t_ns, [ent])
            state = rec.get("state")
            if state is not None and state != self._state:
                self._log_line(t_ns, 2, f"tracker state {self._state or '-'} -> {state} "
                                        f"(frame {rec.get('frame_index')})", "tracker")
                self._state = state
        elif name == COMMANDS and rec.get("limited"):
            self._log_line(t_ns, 3, f"the gate changed the command: {', '.join(rec['limited'])}", "gate")
        elif name == TRUTH_OBJECTS:
            # every object of a multi-object scene where it truly is, coloured by class
            colour = _CLASS_COLOURS.get(rec.get("class"), (0.6, 0.6, 0.6))
            size = max(float(rec.get("size_m") or 0.3), 0.3)
            self._scene_update(t_ns, [self._sphere(f"true_{rec['id']}", t_ns, "world", rec["xyz_m"], size, colour)])
        elif name == TRACKS:
            self._draw_tracks(t_ns, rec)
        elif name not in (METRICS, TRUTH, HEAD, DETECTIONS, COMMANDS):
            ev = rec.get("event")
            self._log_line(t_ns, 2, json.dumps(rec, default=str) if ev is None else
                           f"{ev}: " + json.dumps({k: v for k, v in rec.items() if k not in ("event", "t_ns")},
                                                  default=str), name)

    def _head_tf(self, t_ns, head, lidar, pan_deg, tilt_deg) -> list:
        """The transforms world -> ``head`` -> ``lidar`` at pan, tilt [deg]."""
        x, y, z, w = head_quaternion(float(pan_deg), float(tilt_deg))
        ox, oy, oz = self.lidar_offset_m
        ts = _ts(t_ns)
        return [
            FrameTransform(timestamp=ts, parent_frame_id="world", child_frame_id=head,
                           translation=Vector3(x=0.0, y=0.0, z=0.0), rotation=Quaternion(x=x, y=y, z=z, w=w)),
            FrameTransform(timestamp=ts, parent_frame_id=head, child_frame_id=lidar,
                           translation=Vector3(x=ox, y=oy, z=oz), rotation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
        ]

    def _log_tf(self, t_ns, transforms) -> None:
        self._note(TF)
        self._tf.log(FrameTransforms(transforms=transforms), log_time=self._lt(t_ns))

    def new_file(self) -> None:
        """The MCAP sink was replaced by a new file (:meth:`RecordingWriter.next_segment`): its
        channel ids count again from the first message, and its first head estimate sends a
        keyframe (D and the histories), so the file alone shows them from its start."""
        self.first_log_order = []
        self._seen = set()
        self._head_count = 0

    def end_frame(self) -> None:
        """A frame ends (the next one's points come, or the end): if its head estimate's transforms
        still wait, no truth follows a head estimate in this run; send them, and the next ones as they
        come."""
        if self._pending_tf is not None:
            (t_ns, tfs), self._pending_tf = self._pending_tf, None
            self._truth_expected = False
            self._log_tf(t_ns, tfs)

    def finish(self) -> None:
        """Send what still waits (the last head estimate's transforms); the writer calls it on close."""
        self.end_frame()

    def _scene_update(self, t_ns, entities) -> None:
        self._note(SCENE)
        self._scene.log(SceneUpdate(entities=entities), log_time=self._lt(t_ns))

    @staticmethod
    def _color(rgb, a=1.0):
        return _colour(tuple(rgb), a)

    def _sphere(self, ident, t_ns, frame, xyz, size_m, rgb):
        spheres = [] if xyz is None else [SpherePrimitive(
            pose=Pose(position=Vector3(x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2])),
                      orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
            size=Vector3(x=size_m, y=size_m, z=size_m), color=self._color(rgb, 0.8))]
        return SceneEntity(timestamp=_ts(t_ns), frame_id=frame, id=ident, spheres=spheres)

    def _scene_keyframe(self, t_ns, deleted=()) -> None:
        """D and each trajectory's history so far as one line (entity ``name/history``), on their own
        topic: the newest of these is what a seek restores and what a viewer who joins late gets.
        ``deleted``: the entity ids of histories an earlier keyframe drew and that are gone (a deleted
        track's), removed from the viewer by this one."""
        ents = self._space_entities(t_ns)
        for name, (_stride, pts) in self._history.items():
            rgb = self._path_colors[name]
            ents.append(self._line(f"{name}/history", t_ns, pts, rgb))
        self._keyframed = set(self._history)
        self._note(SCENE_KEYFRAME)
        self._keyframe.log(SceneUpdate(deletions=[self._deletion(t_ns, i) for i in deleted], entities=ents)
                           if deleted else SceneUpdate(entities=ents), log_time=self._lt(t_ns))

    @staticmethod
    def _deletion(t_ns, ident):
        return SceneEntityDeletion(timestamp=_ts(t_ns), type=SceneEntityDeletionType.MatchingId, id=ident)

    # ------------------------------------------------------------------ the multi-object tracker's tracks

    def _draw_tracks(self, t_ns, rec) -> None:
        """Every live track of a /tracks record in one /scene message: entity ``track_<id>/marker`` (a
        sphere at its world position coloured by its label, paler and smaller while tentative, and a
        text facing the camera: ``7 drone``, ``7 drone (fovea, pinned)``, ``9 unknown (tentative, next)``), and its
        history ``track_<id>/path/N`` (10-frame segments; ``track_<id>/path/history`` on the
        keyframes).  A track no longer in the record (deleted) has its entities deleted in the same
        message and its history forgotten: no later keyframe draws it; if the last keyframe drew it, a
        keyframe without it (and deleting it) is sent now, so a seek after the deletion and the live
        view lose it at once."""
        from foveatrack.recording.records import TracksRecord

        r = TracksRecord.from_json(rec)     # a record it cannot read (RecordError) changes nothing drawn
        marks: dict[int, list[str]] = {}
        for tid, word in ((r.fixated, "fovea"), (r.next_target if r.next_target != r.fixated else None, "next"),
                          (r.pinned, "pinned")):
            if tid is not None:
                marks.setdefault(tid, []).append(word)
        ident = Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)
        ents, live = [], {}
        for tr in r.tracks:
            tid = tr.id
            live[tid] = tr.label
            if tr.xyz_m is None or not all(v is not None and math.isfinite(v) for v in tr.xyz_m):
                continue        # no position this frame: what was drawn stays
            rgb, alpha, size = self._track_look(tr.label, tr.confirmed)
            words = ([] if tr.confirmed else ["tentative"]) + marks.get(tid, [])
            text = f"{tid} {tr.label}" + (f" ({', '.join(words)})" if words else "")
            p = [float(v) for v in tr.xyz_m]
            meta = [KeyValuePair(key="label", value=tr.label), KeyValuePair(key="looks_like", value=tr.looks_like),
                    KeyValuePair(key="confirmed", value=str(tr.confirmed).lower()),
                    KeyValuePair(key="score", value="" if tr.score is None else f"{tr.score:.3g}")]
            ents.append(SceneEntity(
                timestamp=_ts(t_ns), frame_id="world", id=f"track_{tid}/marker", metadata=meta,
                spheres=[SpherePrimitive(pose=Pose(position=Vector3(x=p[0], y=p[1], z=p[2]), orientation=ident),
                                         size=Vector3(x=size, y=size, z=size), color=self._color(rgb, alpha))],
                texts=[TextPrimitive(pose=Pose(position=Vector3(x=p[0], y=p[1], z=p[2] + size), orientation=ident),
                                     billboard=True, font_size=14.0, scale_invariant=True,
                                     color=self._color(rgb, 1.0), text=text)]))
            ents.append(self._path_point(f"track_{tid}/path", t_ns, p, rgb))
        deletions, forgotten = [], []
        for tid in sorted(set(self._tracks_drawn) - set(live)):
            name = f"track_{tid}/path"
            seg, _pts = self._paths.pop(name, (-1, []))
            deletions += [self._deletion(t_ns, f"track_{tid}/marker")] + [
                self._deletion(t_ns, f"{name}/{k}") for k in range(seg + 1)]
            for d in (self._history, self._seen_points, self._path_colors):
                d.pop(name, None)
            if name in self._keyframed:
                forgotten.append(f"{name}/history")
        if ents or deletions:
            self._note(SCENE)
            self._scene.log(SceneUpdate(deletions=deletions, entities=ents), log_time=self._lt(t_ns))
        if forgotten:
            self._scene_keyframe(t_ns, forgotten)
        # the track events on /log (before: the whole record, every frame)
        for tid in r.confirmed_now:
            self._log_line(t_ns, 2, f"track {tid} confirmed ({live.get(tid, 'unknown')}, frame {r.frame_id})",
                           "tracks")
        for tid, label in live.items():
            was = self._tracks_drawn.get(tid)
            if was is not None and was != label:
                self._log_line(t_ns, 2, f"track {tid} is now {label} (was {was}, frame {r.frame_id})", "tracks")
        for tid in r.deleted_now:
            self._log_line(t_ns, 2, f"track {tid} deleted (frame {r.frame_id})", "tracks")
        self._tracks_drawn = live

    @staticmethod
    def _track_look(label, confirmed):
        """(rgb, alpha, sphere size [m]) of a track: its label's colour; a tentative track's halfway
        to white, more transparent and smaller."""
        rgb = _CLASS_COLOURS.get(label, _CLASS_COLOURS["unknown"])
        if confirmed:
            return rgb, 0.6, TRACK_MARKER_M[0]
        return tuple(0.5 + 0.5 * c for c in rgb), 0.3, TRACK_MARKER_M[1]

    def _remember(self, name, p3, rgb) -> None:
        stride, pts = self._history.get(name, (1, []))
        self._path_colors[name] = rgb
        self._seen_points[name] = n = self._seen_points.get(name, 0) + 1
        if (n - 1) % stride == 0:
            pts.append(p3)
        if len(pts) > HISTORY_POINTS:        # thin: keep every 2nd point, then take every 2*stride-th
            stride, pts = 2 * stride, pts[::2]
        self._history[name] = (stride, pts)

    def _path_point(self, name, t_ns, xyz, rgb):
        """Add a point to trajectory ``name``: the entity ``name/N`` of its current segment grows by
        one point; a new segment starts at the last point of the one before (no gap)."""
        # one Point3 per point, made once: a segment is re-sent every frame, a history every keyframe
        p3 = Point3(x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2]))
        self._remember(name, p3, rgb)
        seg, pts = self._paths.get(name, (0, []))
        if len(pts) > SEGMENT_FRAMES:
            seg, pts = seg + 1, pts[-1:]
        pts.append(p3)
        self._paths[name] = (seg, pts)
        return self._line(f"{name}/{seg}", t_ns, pts, rgb)

    def _line(self, ident, t_ns, pts, rgb):
        """A line strip through ``pts`` (Point3) as entity ``ident``, frame world."""
        lines = [LinePrimitive(type=LinePrimitiveLineType.LineStrip, thickness=2.0, scale_invariant=True,
                               points=pts, color=self._color(rgb))] if len(pts) >= 2 else []
        return SceneEntity(timestamp=_ts(t_ns), frame_id="world", id=ident, lines=lines)

    def _space_entities(self, t_ns) -> list:
        """D of the tracker config (box or vertical cylinder; a sector or a learned map is not drawn, nor
        a cylinder without its heights: the +-1e9 m of its defaults)."""
        s = self._space
        if not isinstance(s, (Box, Cylinder)) or (isinstance(s, Cylinder) and max(abs(s.z_min_m), abs(s.z_max_m)) >= 1e9):
            return []
        frame = "world" if s.frame == "world" else "lidar"
        ident = Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)
        col = self._color((1.0, 0.8, 0.0), 0.12)
        if isinstance(s, Box):
            lo, hi = np.asarray(s.min_xyz, float), np.asarray(s.max_xyz, float)
            c, size = (lo + hi) / 2, hi - lo
            prim = {"cubes": [CubePrimitive(pose=Pose(position=Vector3(x=c[0], y=c[1], z=c[2]), orientation=ident),
                                            size=Vector3(x=size[0], y=size[1], z=size[2]), color=col)]}
        else:
            cx, cy = (float(v) for v in s.center_xy)
            z0, z1 = float(s.z_min_m), float(s.z_max_m)
            d = 2 * float(s.radius_m)
            prim = {"cylinders": [CylinderPrimitive(
                pose=Pose(position=Vector3(x=cx, y=cy, z=(z0 + z1) / 2), orientation=ident),
                size=Vector3(x=d, y=d, z=z1 - z0), bottom_scale=1.0, top_scale=1.0, color=col)]}
        # frame_locked: D stays where it is defined whatever the transforms do later
        return [SceneEntity(timestamp=_ts(t_ns), frame_id=frame, id="space_of_interest", frame_locked=True, **prim)]

    def _log_line(self, t_ns, level, text, name) -> None:
        lv = {2: LogLevel.Info, 3: LogLevel.Warning, 4: LogLevel.Error}[level]
        self._note(LOG)
        self._log.log(Log(timestamp=_ts(t_ns), level=lv, message=text, name=str(name)), log_time=self._lt(t_ns))
