"""Recordings: one crash-safe file format for the simulator and the daemon (MCAP container).

Why MCAP: it is the ROS 2 default log container, append-only and chunked, with per-chunk CRCs and a
summary at the end that a reader does not need.  Everything up to the last *completed chunk* of a
file cut short (kill -9, power loss) is readable, and Foxglove Studio / ``mcap`` CLI open the files.

Layout of a recording (``profile`` "foveatrack", format version 4, written with the Foxglove SDK;
docs/recordings.md lists every channel):

- an MCAP Metadata record ``foveatrack`` written first, with string values ``format`` =
  "foveatrack-recording", ``format_version`` = "4", ``meta_json`` (the writer's ``meta`` dict as JSON:
  scene/config text, seed, ...), ``foveatrack_version``, ``numpy_version``, ``python_version``,
  ``writer``, ``created_utc``, ``log_time`` (how the MCAP log times were made: "t_ns+OFFSET" [ns], the
  simulator's scene start in UTC, or "host_utc", the daemon's host clock; absent before: t_ns itself);
  after the chunk where channels first appear, a Metadata record
  ``foveatrack_channels`` (``channels_json``: channel id -> name) so that a damaged chunk does not take
  the channel names along.
- channel ``/points``: ``foxglove.PointCloud`` in protobuf, one message per lidar frame, log time from the
  frame's ``t_ns`` (above; its ``timestamp`` is ``t_ns``), ``frame_id`` "lidar", ``pose`` identity, packed points (little-endian, no padding): x, y, z [m, lidar
  frame X forward, Y left, Z up], ``age_ns`` int32 (frame ``t_ns`` − point time [ns], >= 0),
  ``reflectivity`` uint8, and no field outside Foxglove's schema: the frame index is read from the
  frame's ``/detections`` record (format 3 put it and the unit of its ``dt`` in protobuf fields 15
  and 16, read by ``format.decode_points_legacy_v2_v3``).  x, y, z of a frame
  on the Livox mm grid (``foveatrack.livox.protocol.mm_to_m`` of int32 mm, as the client decodes and
  the simulator outputs) are float32 multiples of 2^-11 m within 0.25 mm of the point, from which
  ``rint(1000 v)`` is the mm value exactly; any other frame is float64.  Either way replay gets the
  live values to the bit.
- JSON channels (documented JSON schemas ``foveatrack.Detection`` ..., encoding ``json``), log time =
  the record's ``t_ns``: ``/detections``, ``/commands`` (``raw_hex`` = the bytes sent, ``t_ns`` = send
  time), ``/head`` (head estimates), ``/truth`` (simulation only), ``/metrics``, and any other name
  given to :meth:`RecordingWriter.write`.
- channel ``/imu`` (where the driver feeds the tracker IMU samples): protobuf ``foveatrack.ImuSamples``
  (its FileDescriptorSet is the channel's schema), one message per frame right after the frame's
  points, log time = the frame's ``t_ns``: the samples given to ``Tracker.on_imu`` before the frame
  as packed float64 columns (times [s] as fed, gyro [rad/s], accel [g] where the source has one);
  :meth:`RecordingReader.imu`, :class:`foveatrack.recording.format.ImuSamples`.
- drawn for Foxglove from those records (replay needs none of them): ``/tf`` (FrameTransforms world ->
  head_est -> lidar, world -> head_true -> lidar_true), ``/scene`` (SceneUpdate), ``/log`` (Log).

Format 1 (before the SDK: JSON ``/points`` with base64 data, a channel table in the first metadata
record), format 2 (float64 or plain float32 x, y, z, ``dt_ns`` int32) and format 3 are still read.

Crash safety: records go into the current chunk; the chunk is completed and handed to the OS by
:meth:`RecordingWriter.flush` and automatically when a new frame starts after ``flush_every_frames``
frames (so a chunk holds whole frames with what was written after them).  ``fsync=True`` also
syncs to the disk at each flush.

Damage: each chunk carries a CRC of its records and is followed by a message index.  The reader
skips a damaged chunk (bad CRC, garbage over it or over its length field), finds the next chunk
whose header holds together and whose CRC verifies by scanning the bytes, reads on, and reports
each skipped stretch (:class:`Damage`: bytes, why, messages lost per channel from the index).

Not thread-safe: one writer per thread (a daemon writes from one thread or behind a queue).
:class:`foveatrack.recording.writer_process.RecordingProcess` takes the same calls and writes the same
file from a child process (``simulate --out`` where a core is free).
"""

from foveatrack.recording.export import (export_imu, export_points, export_tracks, export_trajectory,
                                         export_truth_objects)
from foveatrack.recording.format import (COMMANDS, DETECTIONS, FORMAT, FORMAT_VERSION, HEAD, IMU, META_NAME, METRICS,
                                         POINTS, STANDARD_CHANNELS, TRUTH, ImuSamples, Message, PointsFrame,
                                         packed_point_dtype)
from foveatrack.recording.reader import Damage, RecordingReader
from foveatrack.recording.writer import RecordingExistsError, RecordingWriter, RecordingWriteError

__all__ = ["COMMANDS", "DETECTIONS", "FORMAT", "FORMAT_VERSION", "HEAD", "IMU", "META_NAME", "METRICS", "POINTS",
           "STANDARD_CHANNELS", "TRUTH", "Damage", "ImuSamples", "Message", "PointsFrame", "RecordingExistsError",
           "RecordingReader", "RecordingWriteError", "RecordingWriter", "export_imu", "export_points", "export_tracks", "export_trajectory",
           "export_truth_objects", "packed_point_dtype"]
