"""Recordings: one crash-safe file format for the simulator and the daemon (MCAP container).

Why MCAP: it is the ROS 2 default log container, append-only and chunked, with per-chunk CRCs and a
summary at the end that a reader does not need.  Everything up to the last *completed chunk* of a
file cut short (kill -9, power loss) is readable, and Foxglove Studio / ``mcap`` CLI open the files.

Layout of a recording (``profile`` "foveatrack", format version 1):

- an MCAP Metadata record ``foveatrack`` written first, with string values ``format`` =
  "foveatrack-recording", ``format_version`` = "1", ``meta_json`` (the writer's ``meta`` dict as JSON:
  scene/config text, seed, ...), ``channels_json`` (channel id -> name of the standard channels, which
  are defined up front; absent in older files), ``foveatrack_version``, ``numpy_version``,
  ``python_version``, ``created_utc``.
- channel ``/points`` (schema ``foxglove.PointCloud``, JSON encoding, so Foxglove's 3D panel draws it):
  one message per lidar frame, log time = the frame's ``t_ns``, with the standard fields
  ``timestamp {sec, nsec}``, ``frame_id`` = "lidar", ``pose`` (identity), ``point_stride``,
  ``fields``, ``data`` (base64 of the packed points) plus ``frame_index`` and ``t_ns``.  Packed point
  (little-endian, no padding): x, y, z (float64 by default, float32 with ``points_dtype="float32"``)
  [m, lidar frame X forward, Y left, Z up], ``dt_ns`` int32 (point time − frame ``t_ns``, so
  |dt| < 2.1 s), ``reflectivity`` uint8.  float64 keeps the live values bit-exact for replay.
- JSON channels (schema = a small JSON schema, encoding ``json``), log time = the record's ``t_ns``:
  ``/detections``, ``/commands`` (``raw_hex`` = the bytes sent, ``t_ns`` = send time),
  ``/head`` (head estimates), ``/truth`` (simulation only), ``/metrics``, and any other name given to
  :meth:`RecordingWriter.write`.

Crash safety: records go into the current chunk; the chunk is completed and handed to the OS by
:meth:`RecordingWriter.flush` and automatically when a new frame starts after ``flush_every_frames``
frames (so a chunk holds whole frames with what was written after them).  ``fsync=True`` also
syncs to the disk at each flush.

Damage: each chunk carries a CRC of its records and is followed by a message index.  The reader
skips a damaged chunk (bad CRC, garbage over it or over its length field), finds the next chunk
whose header holds together and whose CRC verifies by scanning the bytes, reads on, and reports
each skipped stretch (:class:`Damage`: bytes, why, messages lost per channel from the index).

Not thread-safe: one writer per thread (a daemon writes from one thread or behind a queue).
"""

from foveatrack.recording.export import export_points, export_trajectory
from foveatrack.recording.format import (COMMANDS, DETECTIONS, FORMAT, FORMAT_VERSION, HEAD, META_NAME, METRICS,
                                         POINTS, STANDARD_CHANNELS, TRUTH, Message, PointsFrame, packed_point_dtype)
from foveatrack.recording.reader import Damage, RecordingReader
from foveatrack.recording.writer import RecordingExistsError, RecordingWriter

__all__ = ["COMMANDS", "DETECTIONS", "FORMAT", "FORMAT_VERSION", "HEAD", "META_NAME", "METRICS", "POINTS",
           "STANDARD_CHANNELS", "TRUTH", "Damage", "Message", "PointsFrame", "RecordingExistsError",
           "RecordingReader", "RecordingWriter", "export_points", "export_trajectory", "packed_point_dtype"]
