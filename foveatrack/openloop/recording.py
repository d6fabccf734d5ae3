"""A Foxglove-native recording of an open-loop run (the project's :class:`~foveatrack.recording.RecordingWriter`):
the cloud (``/points``), the track (``/detections`` with the state and track id, drawn as a sphere, and
the trajectory drawn from ``/head``'s ``world_xyz_m``), and the D Algorithm 1 used each frame
(``/openloop_d``: a ``foxglove.SceneUpdate`` cube in the ``lidar`` frame, empty while searching).

The sensor does not move, so the head estimate is pan = tilt = 0 on every frame: the ``lidar`` frame
is the world, and Foxglove draws everything where the sensor saw it.
"""

from __future__ import annotations

import numpy as np

from foveatrack.recording.writer import MAX_POINT_AGE_NS, point_ages_fit

D_TOPIC = "/openloop_d"
# a frame, recorded at its end, holds MAX_POINT_AGE_NS (2.147 s) of points at most: the writer stores
# a point's time as an int32 age (foveatrack.recording.writer.point_ages_fit)
# the frame's end is a float in seconds (a unix time: its last digit is ~0.2 us) rounded back to ns
_ROUNDING_NS = 1_000


def check_frame_length(rate_hz: float, path) -> None:
    """Refuse ``--record`` before anything is read when a frame at ``rate_hz`` lasts longer than a
    recording's frame holds (below ~0.466 Hz): a frame's points reach back its whole length from
    its end.  A rate that is no positive number is left to the sources to refuse."""
    from foveatrack.errors import UserError

    if not (rate_hz > 0 and np.isfinite(rate_hz)):
        return
    length_ns = 1e9 / rate_hz
    if length_ns + _ROUNDING_NS > MAX_POINT_AGE_NS:
        least = 1e9 / (MAX_POINT_AGE_NS - _ROUNDING_NS)
        raise UserError(f"--record {path}: a frame at --rate-hz {rate_hz:g} lasts {length_ns * 1e-9:.3g} s, longer "
                        f"than the {MAX_POINT_AGE_NS * 1e-9:.3f} s of points a recording's frame holds (each point's "
                        f"time is stored as int32 ns before its frame's end): give --rate-hz {least:.3f} or more, "
                        f"or track without --record")


class TrackRecorder:
    """``observer(k, arrival_s, frame, out)`` for :func:`foveatrack.openloop.run.track_source`;
    use as a context manager (the file is closed on exit)."""

    def __init__(self, path, meta: dict, overwrite: bool = False):
        from foxglove.channels import SceneUpdateChannel

        from foveatrack.recording import RecordingWriter

        self.writer = RecordingWriter(path, {"source": "openloop", **meta}, overwrite=overwrite)
        self._d = SceneUpdateChannel(D_TOPIC, context=self.writer.context)

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self.writer.close()

    def __call__(self, k: int, arrival_s: float, frame, out) -> None:
        from foxglove.messages import (Color, CubePrimitive, Pose, Quaternion, SceneEntity, SceneUpdate,
                                       Timestamp, Vector3)

        w = self.writer
        t_ns = int(round(frame.t_end_s * 1e9))
        if not point_ages_fit(t_ns, frame.t_ns):
            from foveatrack.errors import UserError

            lo, hi = (int(frame.t_ns.min()) - t_ns) * 1e-9, (int(frame.t_ns.max()) - t_ns) * 1e-9
            raise UserError(f"--record {w.path}: frame {k} (at {frame.t_start_s:.6f} s) has points from "
                            f"{lo:+.3f} s to {hi:+.3f} s "
                            f"of its end, beyond the ±{MAX_POINT_AGE_NS * 1e-9:.3f} s a recording's frame holds (each "
                            f"point's time is stored as int32 ns from its frame's end); the frames before it are "
                            f"recorded; track without --record to read it all")
        w.write_points(t_ns, k, frame.xyz, frame.t_ns, frame.reflectivity)
        det = out.detection
        xyz = None if det is None else np.asarray(det.xyz, float)
        w.write_detection(t_ns, k, det is not None, xyz_m=xyz, n_points=0 if det is None else det.n_points,
                          state=out.state, track_id=out.track_id)
        w.write_head_estimate(t_ns, 0.0, 0.0, frame_id=k, world_xyz_m=None if xyz is None else xyz.tolist())
        cubes = []
        if out.d_min_m is not None:
            c, size = (out.d_min_m + out.d_max_m) / 2, out.d_max_m - out.d_min_m
            cubes.append(CubePrimitive(
                pose=Pose(position=Vector3(x=float(c[0]), y=float(c[1]), z=float(c[2])),
                          orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
                size=Vector3(x=float(size[0]), y=float(size[1]), z=float(size[2])),
                color=Color(r=1.0, g=0.8, b=0.0, a=0.15)))
        ts = Timestamp(sec=t_ns // 1_000_000_000, nsec=t_ns % 1_000_000_000)
        self._d.log(SceneUpdate(entities=[SceneEntity(timestamp=ts, frame_id="lidar", id="space_of_interest",
                                                      cubes=cubes)]), log_time=t_ns)
