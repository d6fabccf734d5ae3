"""ROS 1 bags (``.bag``) and ROS 2 bags (a bag folder, or its ``.mcap`` / ``.db3`` file) through
``rosbags`` (pure Python, no ROS install): ``sensor_msgs/msg/PointCloud2`` and the Livox
``CustomMsg`` of ``livox_ros_driver2`` (ROS 2) and ``livox_ros_driver`` (ROS 1).

The Livox definitions are registered with rosbags' typestore here (a bag that embeds its own
definitions, as ROS 1 bags and MCAP do, is read with those).

PointCloud2: any field layout with ``x``, ``y``, ``z`` (any numeric type, either byte order: the
``is_bigendian`` flag's, unless the float coordinates read so are mostly nonsense and read the other
way sane, when the flag is said to be wrong and overruled);
``intensity`` (or ``reflectivity``) is kept as reflectivity; a per-point time is read from the first
of ``timestamp``, ``time``, ``t``, ``offset_time``.  Its unit is not in the message; it is taken from
the field's datatype and name, as the drivers publish them (:func:`point_times_ns`):

* an integer field is ns after ``header.stamp`` (Livox ``offset_time`` and Ouster ``t``: uint32);
* a float64 field named ``timestamp`` is an absolute time, in ns (livox_ros_driver2) or seconds
  (Hesai, RoboSense): the two are nine orders of magnitude apart, told by whether its values reach 1e15;
* any other float field is seconds after ``header.stamp`` (Velodyne ``time``: float32).

A scan's times are then checked against its ``header.stamp``: spread over more than a second (or a
frame period, if longer), they cannot be a scan's, and its points are put at the stamp; lying more
than that from the stamp (a driver stamping points on another clock: GPS time is 18 s ahead of UTC),
they are read from the scan's first point on, placed at the stamp.  Either is said once per topic.
CustomMsg: point time = ``timebase + offset_time`` [ns], checked the same way.

The frame of a message starts at its ``header.stamp`` (:mod:`foveatrack.sources.stamps`); its
arrival is the bag's log time.  Messages are read in the bag's order: stamps that go back or repeat
are counted and said once at the end; a topic whose first messages all share one stamp (0: never
set) is refused.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from foveatrack.errors import UserError
from foveatrack.mcap_names import MCAP_MAGIC, META_NAME
from foveatrack.sources.stamps import StampedFrame, check_rate, frame_from_cloud, period_ns, seconds, warn_stderr
from foveatrack.sources.tf import TF_TYPES, TfBuffer, apply

POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
LIVOX_CUSTOM = ("livox_ros_driver2/msg/CustomMsg", "livox_ros_driver/msg/CustomMsg")
CLOUD_TYPES = (POINTCLOUD2,) + LIVOX_CUSTOM

LIVOX_CUSTOM_POINT_MSG = """\
uint32 offset_time
float32 x
float32 y
float32 z
uint8 reflectivity
uint8 tag
uint8 line
"""

LIVOX_CUSTOM_MSG = """\
std_msgs/Header header
uint64 timebase
uint32 point_num
uint8 lidar_id
uint8[3] rsvd
{pkg}/CustomPoint[] points
"""

# PointField.datatype -> numpy type (sensor_msgs/msg/PointField)
_POINTFIELD = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}
_TIME_FIELDS = ("timestamp", "time", "t", "offset_time")
#: how far a scan's point times may spread, and lie from its header.stamp, at the least [ns]
_SCAN_SPAN_NS = 1_000_000_000


def livox_typestore(base=None):
    """A rosbags typestore with the ROS 2 standard messages and both Livox drivers' CustomMsg."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = base or get_typestore(Stores.LATEST)
    types = {}
    for pkg in ("livox_ros_driver2", "livox_ros_driver"):
        types.update(get_types_from_msg(LIVOX_CUSTOM_POINT_MSG, f"{pkg}/msg/CustomPoint"))
        types.update(get_types_from_msg(LIVOX_CUSTOM_MSG.format(pkg=pkg), f"{pkg}/msg/CustomMsg"))
    store.register(types)
    return store


class BagSource:
    """Iterable of ``(arrival_s, Frame)`` over one cloud topic of a ROS 1 or ROS 2 bag."""

    kind = "ros bag"

    def __init__(self, path, topic: str | None, rate_hz: float = 10.0, fixed_frame: str | None = None,
                 warn=None):
        self.path = Path(path)
        self.rate_hz = check_rate(rate_hz)
        self.fixed_frame = fixed_frame
        #: where what is read with a loss or a guess is said (default: stderr)
        self.warn = warn or warn_stderr
        topics = self._topics()
        if topic is None:
            clouds = [name for name, (t, _) in topics.items() if t in CLOUD_TYPES]
            if len(clouds) != 1:
                raise UserError(f"{self.path}: give the cloud topic with --topic; the bag has "
                                + describe_topics(topics))
            topic = clouds[0]     # the bag's only point cloud: what --topic would name
            self.warn(f"{self.path}: reading {topic}, the bag's only point-cloud topic (--topic names another)")
        if topic not in topics:
            raise UserError(f"{self.path}: no topic {topic!r}; the bag has " + describe_topics(topics))
        msgtype, n = topics[topic]
        if msgtype not in CLOUD_TYPES:
            raise UserError(f"{self.path}: topic {topic} carries {msgtype}, which is not a point cloud "
                            f"this reads ({', '.join(CLOUD_TYPES)})")
        self.topic, self.msgtype, self.n_messages = topic, msgtype, n
        if n == 0 and not self._has_a_message():
            raise UserError(f"{self.path}: topic {topic} has no messages, so there is nothing to track; the bag "
                            "has " + describe_topics(topics))
        self._tf_topics = [name for name, (t, _) in topics.items() if t in TF_TYPES]
        if fixed_frame is not None and not self._tf_topics:
            raise UserError(f"{self.path}: --fixed-frame {fixed_frame} needs a /tf topic (tf2_msgs/msg/TFMessage); "
                            "the bag has " + describe_topics(topics))

    def __len__(self) -> int:
        return self.n_messages

    def _has_a_message(self) -> bool:
        """Whether the topic has a message, read, where its count says none (a ROS 2 bag's count is its
        metadata.yaml's); a read that fails is left to the iteration to say."""
        try:
            with self._reader() as r:
                conns = [c for c in r.connections if c.topic == self.topic]
                return next(iter(r.messages(connections=conns)), None) is not None
        except Exception:
            return True

    def _reader(self):
        from rosbags.highlevel import AnyReader

        return AnyReader([self.path], default_typestore=livox_typestore())

    def _topics(self) -> dict[str, tuple[str, int]]:
        try:
            with self._reader() as r:
                return {name: (info.msgtype, info.msgcount) for name, info in r.topics.items()}
        except Exception as exc:   # rosbags raises its own errors, KeyError/struct errors on damage
            raise _unreadable(self.path, exc) from None

    def __iter__(self):
        try:
            reader = self._reader()
            reader.open()
        except Exception as exc:
            raise _unreadable(self.path, exc) from None
        try:
            tf = self._read_tf(reader) if self.fixed_frame is not None else None
            conns = [c for c in reader.connections if c.topic == self.topic]
            msgs = reader.messages(connections=conns)
            note = _once(self.warn)
            stamps = _StampOrder(self.path, self.topic, self.n_messages)
            k = 0
            while True:
                try:
                    item = next(msgs)
                except StopIteration:
                    break
                except Exception as exc:
                    raise UserError(f"{self.path}: topic {self.topic}: the bag is damaged after message {k} "
                                    f"({_one_line(exc)})") from None
                conn, log_ns, raw = item
                try:
                    msg = reader.deserialize(raw, conn.msgtype)
                except Exception as exc:
                    raise UserError(f"{self.path}: topic {self.topic}: message {k} is not a readable "
                                    f"{conn.msgtype} ({_one_line(exc)})") from None
                stamps.see(k, _stamp_ns(msg))
                where = f"{self.path}: topic {self.topic} ({conn.msgtype}) message {k}"
                if conn.msgtype == POINTCLOUD2:
                    fr = frame_from_pointcloud2(msg, self.rate_hz, where, note)
                else:
                    fr = frame_from_livox_custom(msg, self.rate_hz, where, note)
                if tf is not None and fr.n_points:
                    R, t = tf.lookup(self.fixed_frame, msg.header.frame_id, _stamp_ns(msg), where)
                    fr = type(fr)(fr.t_start_s, fr.t_end_s, apply(R, t, fr.xyz), fr.t_ns, fr.reflectivity)
                k += 1
                yield StampedFrame(seconds(log_ns), fr)
            stamps.end(k, self.warn)
        finally:
            reader.close()


    def _read_tf(self, reader) -> TfBuffer:
        """Every transform of the bag's tf topics (``/tf_static``'s are static)."""
        buf = TfBuffer()
        conns = [c for c in reader.connections if c.topic in self._tf_topics]
        try:
            for conn, _log_ns, raw in reader.messages(connections=conns):
                msg = reader.deserialize(raw, conn.msgtype)
                static = conn.topic.rstrip("/").endswith("tf_static")
                for ts in msg.transforms:
                    tr, q = ts.transform.translation, ts.transform.rotation
                    buf.add(ts.header.frame_id, ts.child_frame_id, _stamp_ns(ts),
                            (tr.x, tr.y, tr.z), (q.x, q.y, q.z, q.w), static)
        except UserError:
            raise
        except Exception as exc:
            raise UserError(f"{self.path}: the tf topics ({', '.join(self._tf_topics)}) are not readable "
                            f"({_one_line(exc)})") from None
        return buf


class _StampOrder:
    """A topic's header stamps, which are its frames' times: the first ``SAME_LIMIT`` messages (or all,
    if fewer) at one stamp are refused (a publisher that does not stamp its clouds: every frame at
    one time), a stamp not after the message before's is counted and said once at the end (the
    messages are read in the bag's order)."""

    SAME_LIMIT = 10

    def __init__(self, path: Path, topic: str, n_messages: int):
        self.path, self.topic, self.n_messages = path, topic, n_messages
        self.first = self.prev = None
        self.all_same = True
        self.n_back, self.first_back = 0, None

    def see(self, k: int, stamp: int) -> None:
        if k == 0:
            self.first = stamp
        else:
            self.all_same = self.all_same and stamp == self.first
            if stamp <= self.prev:
                self.n_back += 1
                self.first_back = self.first_back or (k, stamp, self.prev)
        self.prev = stamp
        if k >= 1 and self.all_same and k + 1 == min(self.n_messages, self.SAME_LIMIT):
            self._refuse(k + 1)

    def end(self, n: int, warn) -> None:
        if n >= 2 and self.all_same:
            self._refuse(n)
        if self.n_back:
            k, stamp, prev = self.first_back
            warn(f"{self.path}: topic {self.topic}: {self.n_back} of its {n} messages have a header.stamp not "
                 f"after the message before's (the first: message {k} at {stamp * 1e-9:.6f} s, after "
                 f"{prev * 1e-9:.6f} s); they were read in the bag's order")

    def _refuse(self, n: int):
        unset = " (0: never set)" if self.first == 0 else ""
        raise UserError(f"{self.path}: topic {self.topic}: the first {n} messages all have header.stamp "
                        f"{self.first * 1e-9:.6f} s{unset}; a frame's time is its header.stamp, so these frames "
                        f"cannot be told apart in time (the publisher does not stamp its clouds)")


def describe_topics(topics: dict[str, tuple[str, int]]) -> str:
    if not topics:
        return "no topics"
    parts = [f"{name} ({t}, {n} messages{'' if t in CLOUD_TYPES else ', not a cloud'})"
             for name, (t, n) in sorted(topics.items())]
    return "; ".join(parts)


ROS1_MAGIC = b"#ROSBAG V2.0\n"
SQLITE_MAGIC = b"SQLite format 3\x00"
# what a file that is no bag may be instead, by its first bytes
_NOT_BAGS = ((b"\x1f\x8b", "gzip-compressed data (gunzip it first)"),
             (b"BZh", "bzip2-compressed data (unpack it first)"),
             (b"\xfd7zXZ\x00", "xz-compressed data (unpack it first)"),
             (b"\x28\xb5\x2f\xfd", "zstd-compressed data (unpack it first)"), (b"PK\x03\x04", "a zip archive"),
             (b"#ROSBAG V1.", "a ROS 1 bag of the old format V1.x (rosbags reads V2.0)"),
             (b"livox_tech", "a Livox Viewer .lvx file"), (b"\x93NUMPY", "a numpy .npy file"),
             (b"# .PCD", "a PCD file"))


def _unreadable(path: Path, exc: Exception) -> UserError:
    """The error for a bag rosbags cannot open: what the file is by its first bytes (foveatrack's own
    recording, another kind of file, a ROS 1 magic with no bag after it), else the reader's reason,
    and for a bag cut short -- a ROS 1 bag whose header record holds together, a ROS 2 bag -- what
    mends it."""
    why = _one_line(exc)
    if path.is_dir():
        return UserError(f"{path}: not a readable bag ({_mend(why)})")
    try:
        with open(path, "rb") as fh:
            head = fh.read(64)
        size = path.stat().st_size
    except OSError as e:
        return UserError(f"{path}: cannot read it ({e.strerror or e})")
    if head.startswith(MCAP_MAGIC) and _is_foveatrack_recording(path):
        return UserError(f"{path}: a foveatrack recording (its MCAP metadata names it; `simulate --out`, the "
                         f"daemon and `track --record` write these), not a ROS bag: `foveatrack replay {path}` re-runs "
                         f"the tracker over a simulator's or a daemon's, `foveatrack export {path}` writes its points "
                         f"as .lvx, CSV or NPZ")
    kinds = {ROS1_MAGIC: ("a ROS 1 bag", ".bag"), MCAP_MAGIC: ("an MCAP file (a ROS 2 bag's storage)", ".mcap"),
             SQLITE_MAGIC: ("an SQLite file (a ROS 2 bag's storage)", ".db3")}
    magic = next((m for m in kinds if head.startswith(m)), None)
    if magic is None:
        return UserError(f"{path}: not a ROS bag: it does not start with the ROS 1 bag header '#ROSBAG V2.0' "
                         f"(nor with the MCAP or SQLite header of a ROS 2 bag); its first bytes are "
                         f"{_first_bytes(head, size)}")
    what, ext = kinds[magic]
    if path.suffix.lower() != ext:
        return UserError(f"{path}: {what}, named {path.suffix or 'without a suffix'}: name it {ext} "
                         f"(the suffix says how to read it)")
    if magic == ROS1_MAGIC:
        wrong = _ros1_header_problem(path, size)
        if wrong is not None:
            return UserError(f"{path}: not a ROS bag: it starts with the ROS 1 bag magic '#ROSBAG V2.0', but no "
                             f"bag header record follows it ({wrong}); a bag cut short keeps its header, so this "
                             f"is no bag 'rosbag reindex' can mend")
    return UserError(f"{path}: not a readable bag ({_mend(why)})")


def _mend(why: str) -> str:
    """The reader's reason, and for a bag whose end or index is missing (its recorder was stopped
    short: the usual state of a killed recording) what mends it."""
    if any(k in why for k in ("index", "Header could not be read", "end magic", "magic is invalid")):
        why += ("; a bag whose recorder was stopped short has no index or end: 'rosbag reindex BAG' (ROS 1) or "
                "'ros2 bag reindex DIR' (ROS 2) writes them, then read it again")
    return why


def _ros1_header_problem(path: Path, size: int) -> str | None:
    """None if the ROS 1 magic is followed by a bag header record (op 0x03) within the file, as every
    bag has from its first write on; else what follows it instead."""
    with open(path, "rb") as fh:
        fh.seek(len(ROS1_MAGIC))
        raw = fh.read(4)
        if len(raw) < 4:
            return f"the file ends {size - len(ROS1_MAGIC)} bytes after it"
        n = int.from_bytes(raw, "little")
        if len(ROS1_MAGIC) + 4 + n > size:
            return f"its first record's header length, {n} bytes, runs past the file's {size} bytes"
        hdr = fh.read(n)
    fields, i = {}, 0
    while i + 4 <= n:
        k = int.from_bytes(hdr[i:i + 4], "little")
        name, eq, value = hdr[i + 4:i + 4 + k].partition(b"=")
        if i + 4 + k > n or not eq:
            return "its first record's header fields do not hold together"
        fields[name] = value
        i += 4 + k
    if fields.get(b"op") != b"\x03":
        return "its first record is not a bag header (op 0x03)"
    return None


def _first_bytes(head: bytes, size: int) -> str:
    if size == 0:
        return "none: the file is empty"
    like = next((w for m, w in _NOT_BAGS if head.startswith(m)), None)
    shown = repr(head[:16]) + (" ..." if size > 16 else "")
    return f"{shown}, {like}" if like else shown


def _is_foveatrack_recording(path: Path) -> bool:
    """An MCAP file foveatrack's recording writer wrote: its Header's profile or a metadata record,
    which the writer puts before any message, names foveatrack."""
    from mcap.records import Chunk, Header, Message, Metadata
    from mcap.stream_reader import StreamReader

    try:
        with open(path, "rb") as fh:
            for k, rec in enumerate(StreamReader(fh, skip_magic=False).records):
                if isinstance(rec, Header) and rec.profile == META_NAME:
                    return True
                if isinstance(rec, Metadata) and rec.name == META_NAME:
                    return True
                if isinstance(rec, (Chunk, Message)) or k > 100:
                    return False
    except Exception:      # damage: it says no more than its records before it
        return False
    return False


def _once(warn):
    """``note(key, line)``: ``warn(line)`` the first time ``key`` is noted, then nothing."""
    seen = set()

    def note(key: str, line: str) -> None:
        if key not in seen:
            seen.add(key)
            warn(line)
    return note


def _one_line(exc: BaseException) -> str:
    s = " ".join(str(exc).split())
    return s[:200] if s else type(exc).__name__


def _stamp_ns(msg) -> int:
    st = msg.header.stamp
    # ROS 2 builtin_interfaces/Time (sec, nanosec); rosbags gives ROS 1 time the same fields
    return int(st.sec) * 1_000_000_000 + int(st.nanosec)


def pointcloud2_xyz(msg, where: str, note=None):
    """``(xyz (N,3) float64, t (N,) as the field holds it or None, time field name or None, intensity
    or None)`` of a PointCloud2, by its field layout and byte order (a wrong ``is_bigendian`` flag
    is overruled, :func:`_byte_order`; ``note(key, line)`` hears it)."""
    note = note or (lambda key, line: warn_stderr(line))
    fields = {f.name: f for f in msg.fields}
    missing = [k for k in ("x", "y", "z") if k not in fields]
    if missing:
        raise UserError(f"{where}: PointCloud2 has no field {', '.join(missing)} "
                        f"(fields: {', '.join(fields) or 'none'})")
    n = int(msg.width) * int(msg.height)
    step = int(msg.point_step)
    data = np.asarray(msg.data, dtype=np.uint8)
    if n and (step <= 0 or data.size < n * step):
        raise UserError(f"{where}: PointCloud2 data holds {data.size} bytes, fewer than width*height*point_step "
                        f"= {n}*{step}")
    flagged = ">" if msg.is_bigendian else "<"

    def column(name, order):
        f = fields[name]
        code = _POINTFIELD.get(int(f.datatype))
        if code is None:
            raise UserError(f"{where}: PointCloud2 field {name} has unknown datatype {f.datatype}")
        dt = np.dtype(order + code)
        if int(f.offset) + dt.itemsize > step:
            raise UserError(f"{where}: PointCloud2 field {name} (offset {f.offset}) lies outside point_step {step}")
        rec = np.dtype({"names": [name], "formats": [dt], "offsets": [int(f.offset)], "itemsize": step})
        return np.frombuffer(data[: n * step].tobytes(), dtype=rec, count=n)[name]

    def points(order):
        xyz = np.empty((n, 3), dtype=np.float64)
        for i, k in enumerate("xyz"):
            xyz[:, i] = column(k, order)
        return xyz

    with np.errstate(all="ignore"):       # bytes that are no number (a wrong flag, damage) are judged below
        xyz, order = points(flagged), flagged
        if n and all(int(fields[k].datatype) in (7, 8) for k in "xyz"):
            order = _byte_order(xyz, flagged, points, where, note)
            if order != flagged:
                xyz = points(order)
        tname = next((k for k in _TIME_FIELDS if k in fields), None)
        t = column(tname, order) if tname else None
        iname = next((k for k in ("intensity", "reflectivity") if k in fields), None)
        inten = column(iname, order) if iname else None
    return xyz, t, tname, inten


def _implausible(xyz: np.ndarray) -> float:
    """The share of a cloud's coordinates that no lidar gives: of those that are neither 0 nor NaN
    (padding, no return), the ones infinite or off 0.1 mm .. 10 km.  A float read in the wrong byte
    order is mostly that (denormal or huge); 0 for a cloud with none to judge."""
    v = np.abs(xyz[~np.isnan(xyz) & (xyz != 0)])
    return float(np.count_nonzero(~((v >= 1e-4) & (v <= 1e4)))) / v.size if v.size else 0.0


def _byte_order(xyz: np.ndarray, flagged: str, points, where: str, note) -> str:
    """The byte order to read a cloud's floats in: its ``is_bigendian`` flag's, unless most of its
    coordinates are implausible read so while read the other way at most a quarter as many are (a
    driver setting the flag wrong), said once."""
    bad = _implausible(xyz)
    if bad <= 0.5:
        return flagged
    other = "<" if flagged == ">" else ">"
    bad_other = _implausible(points(other))
    if bad_other * 4 >= bad:
        return flagged
    name = {">": "big-endian", "<": "little-endian"}
    note("byte-order", f"{where}: is_bigendian is {flagged == '>'}, but read {name[flagged]} {bad:.0%} of its "
                       f"coordinates (leaving out 0 and NaN) are denormal, infinite, or beyond 10 km, where read "
                       f"{name[other]} {bad_other:.0%} are: the is_bigendian flag is taken to be wrong and the data "
                       f"read {name[other]} (said for the first such message only)")
    return other


def frame_from_pointcloud2(msg, rate_hz: float, where: str, note=None):
    """The frame of a PointCloud2; ``note(key, line)`` hears what is read with a guess (default: a
    warning each time)."""
    note = note or (lambda key, line: warn_stderr(line))
    stamp = _stamp_ns(msg)
    xyz, t, tname, inten = pointcloud2_xyz(msg, where, note)
    t_ns = None
    if t is not None and t.size:
        t_ns = point_times_ns(t, tname, stamp, period_ns(rate_hz), where, note)
    refl = None if inten is None else np.clip(np.nan_to_num(inten), 0, 255).astype(np.uint8)
    return frame_from_cloud(stamp, xyz, rate_hz, t_ns, refl)


def point_times_ns(t: np.ndarray, name: str, stamp_ns: int, period: int, where: str, note) -> np.ndarray | None:
    """Per-point times [ns] of a PointCloud2 time field ``t`` (its values as the field holds them),
    the unit taken from its datatype and name (the module's rules); None when they cannot be a
    scan's (the points are then at the stamp)."""
    dt = t.dtype
    with np.errstate(all="ignore"):
        if dt.kind in "iu":
            how = f"{name} ({dt.name}): ns after header.stamp"
            off = t.astype(np.float64)
            exact = lambda: stamp_ns + t.astype(np.int64)                   # noqa: E731
        elif name == "timestamp" and dt.itemsize == 8:
            finite = t[np.isfinite(t)]
            in_ns = finite.size > 0 and float(np.median(np.abs(finite))) >= 1e15
            how = f"{name} (float64): absolute {'ns' if in_ns else 'seconds'}"
            off = t - float(stamp_ns) if in_ns else t * 1e9 - float(stamp_ns)
            exact = (lambda: np.round(t).astype(np.int64)) if in_ns else (lambda: np.round(t * 1e9).astype(np.int64))
        else:
            how = f"{name} ({dt.name}): seconds after header.stamp"
            off = t.astype(np.float64) * 1e9
            exact = lambda: stamp_ns + np.round(t.astype(np.float64) * 1e9).astype(np.int64)  # noqa: E731
        return _near_stamp(off, exact, stamp_ns, period, where, how, note)


def _near_stamp(off: np.ndarray, exact, stamp_ns: int, period: int, where: str, how: str, note):
    """A scan's point times from their offsets ``off`` [ns, float64] from its stamp: ``exact()``
    (int64 ns) when they lie near the stamp, counted from the first point when they lie on another
    clock, None when they spread over more than a scan can."""
    good = np.isfinite(off)
    if not good.any():
        return None
    lo, hi = float(off[good].min()), float(off[good].max())
    span = max(_SCAN_SPAN_NS, period)
    if hi - lo > span:
        note("time-span", f"{where}: the points' time field {how} spreads one scan over {(hi - lo) * 1e-9:.4g} s, "
                          f"which no scan lasts: not a unit this reads; the points are put at header.stamp "
                          f"(said for the first such message only)")
        return None
    if lo >= -span and hi <= span:
        t_ns = exact()
    else:
        note("time-clock", f"{where}: the points' time field {how} puts the scan's first point "
                           f"{lo * 1e-9:+.3f} s from header.stamp: the points are stamped on another clock than "
                           f"the header (GPS time, for one, is 18 s ahead of UTC); each scan's first point is put "
                           f"at its header.stamp, the others kept after it (said for the first such message only)")
        if max(-lo, hi) < 2.0**62:      # in int64: the times as exact as the field holds them
            t_ns = exact()
            t_ns = stamp_ns + (t_ns - t_ns[good].min())
        else:
            t_ns = stamp_ns + np.round(np.where(good, off - lo, 0.0)).astype(np.int64)
    if not good.all():
        t_ns = np.where(good, t_ns, stamp_ns)
    return t_ns


def frame_from_livox_custom(msg, rate_hz: float, where: str, note=None):
    note = note or (lambda key, line: warn_stderr(line))
    pts = msg.points
    n = len(pts)
    xyz = np.empty((n, 3), dtype=np.float64)
    off = np.empty(n, dtype=np.int64)
    refl = np.empty(n, dtype=np.uint8)
    for i, p in enumerate(pts):
        xyz[i, 0], xyz[i, 1], xyz[i, 2] = p.x, p.y, p.z
        off[i] = p.offset_time
        refl[i] = p.reflectivity
    stamp = _stamp_ns(msg)
    t_ns = None
    if n:
        base = int(msg.timebase) - stamp
        t_ns = _near_stamp(base + off.astype(np.float64), lambda: int(msg.timebase) + off, stamp,
                           period_ns(rate_hz), where, "timebase + offset_time: ns", note)
    return frame_from_cloud(stamp, xyz, rate_hz, t_ns, refl)
