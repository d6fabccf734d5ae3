"""Record a closed-loop run into the one recording format (MCAP, :mod:`foveatrack.recording`).

Channels and fields, shared with the daemon so ``foveatrack replay`` reads both:

The per-frame records are :mod:`foveatrack.recording.records`' (the daemon writes the same):

* points: per frame, ``t_ns`` = frame end, xyz in the lidar frame, per-point ``t_ns``, reflectivity
* detections: ``detected``, ``xyz_m`` (lidar frame), ``n_points``, ``az_deg``, ``el_deg``, ``state``,
  ``error_pan_deg``, ``error_tilt_deg``
* commands: ``raw_hex`` as written (Pelco-D), ``t_ns`` = send time, plus the decoded speeds
* head: the tracker's reconstruction (``pan_deg``, ``tilt_deg``, sigmas, ``world_xyz_m``)
* truth (simulation only): true head pose and target position at frame mid, true error
* imu (scenes with ``[imu]``): the head gyro's samples fed to the tracker before the frame
* truth_objects (multi-object scenes, ``Scene.multi_object``): every object's id, class, position,
  velocity, size and the rays that hit it, one record per object and frame (sim.objects_truth)
* tracks (scenes with ``[tracker.sky]``): every track and the fovea's schedule, one record per frame
"""

from __future__ import annotations

from foveatrack.fixed_order import floats3
from foveatrack.recording import RecordingWriter
from foveatrack.recording.run_meta import RecordingMeta, SimulatorOrigin
from foveatrack.recording.records import (CommandRecord, ObjectTruthRecord, TruthRecord, ns, write_record,
                                          write_tracker_frame)


def recording_meta(scene, loop) -> dict:
    """The recording's metadata (:class:`foveatrack.recording.run_meta.RecordingMeta`) from what the loop
    runs: its tracker's configuration (with any change made in code, e.g. a Monte-Carlo gain), speed
    table and gate, never from the scene's raw ``[tracker]`` table."""
    from dataclasses import asdict

    from sim.summary import half_fov_deg

    origin = SimulatorOrigin(scene.name, scene.path, scene.text, scene.seed, tuple(sorted(scene.effects)),
                             asdict(scene.gimbal))
    return RecordingMeta(loop.tracker.config, loop.head_facts.tracker_values(), loop.tracker.table,
                         loop.gate.limits, origin, point_rate_hz=scene.optics.point_rate_hz,
                         # replay's "in the FoV", as the simulator's summary has it
                         half_fov_deg=half_fov_deg(scene),
                         sky=None if loop.sky is None else loop.sky.sky_table()).to_dict()


class SimRecorder:
    """A ``frame_hook`` for :class:`sim.loop.ClosedLoop` that writes every frame."""

    def __init__(self, writer: RecordingWriter):
        self.writer = writer
        self.frame_id = 0

    def __call__(self, frame, out, loop) -> None:
        w = self.writer
        fid = self.frame_id
        t_end = write_tracker_frame(w, fid, frame, out, loop.imu_fed)
        c = loop.last_command   # as sent, after the gate
        if loop.last_sent is not None:
            t_send, data = loop.last_sent
            t = out.command   # the tracker's, recorded when the gate changed it (as the daemon records it)
            write_record(w, CommandRecord(ns(t_send), data, c.pan_dir, c.pan_byte, c.tilt_dir, c.tilt_byte,
                                          frame_id=fid, limited=tuple(loop.last_limited),
                                          tracker_command=(t.pan_dir, t.pan_byte, t.tilt_dir, t.tilt_byte)))
        L = loop.log
        write_record(w, TruthRecord(t_end, fid, L.head_pan_deg[-1], L.head_tilt_deg[-1],
                                    tuple(floats3(L.target_xyz[-1])), L.true_error_deg[-1],
                                    L.points_on_target[-1]))
        for o in loop.last_objects or ():
            write_record(w, ObjectTruthRecord(t_end, fid, o.id, o.cls, o.xyz_m, o.velocity_m_s, o.size_m, o.rays_hit))
        self.frame_id += 1
