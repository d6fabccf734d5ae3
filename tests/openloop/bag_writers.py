"""Write the same frames as a ROS 2 bag (MCAP), a ROS 1 bag (both through ``rosbags``'s writers,
PointCloud2 and Livox CustomMsg) and a PCD folder (``pypcd4``), for the readers' tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from foveatrack.sources import ns_from_file_stem
from foveatrack.sources.rosbag import livox_typestore

PERIOD_NS = 100_000_000


def npy_frames(folder) -> list[tuple[int, np.ndarray]]:
    out = [(ns_from_file_stem(f.name[:-4]), np.load(f)) for f in Path(folder).glob("*.npy")]
    return sorted(out, key=lambda x: x[0])


def _stores(ros1: bool):
    from rosbags.typesys import Stores, get_typestore

    store = livox_typestore(get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE))
    if ros1:   # rosbags' Noetic store has no tf2_msgs; its definition is one line
        from rosbags.typesys import get_types_from_msg

        store.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
    return store


def _header(store, ns: int, ros1: bool, frame_id="livox_frame"):
    Time = store.types["builtin_interfaces/msg/Time"]
    Header = store.types["std_msgs/msg/Header"]
    stamp = Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
    return Header(seq=0, stamp=stamp, frame_id=frame_id) if ros1 else Header(stamp=stamp, frame_id=frame_id)


def pointcloud2(store, ns, xyz, ros1, *, float64=True, extra_intensity=True, drop=()):
    """A PointCloud2 with fields x, y, z (float64 or float32), and intensity (float32), in that
    layout plus 2 bytes of padding per point (any layout must do); ``drop`` leaves fields out."""
    PointField = store.types["sensor_msgs/msg/PointField"]
    PointCloud2 = store.types["sensor_msgs/msg/PointCloud2"]
    ft, size = (8, 8) if float64 else (7, 4)
    names = [k for k in ("x", "y", "z") if k not in drop]
    fields, off = [], 0
    dt_names, dt_formats, dt_offsets = [], [], []
    for k in names:
        fields.append(PointField(name=k, offset=off, datatype=ft, count=1))
        dt_names.append(k), dt_formats.append("<f8" if float64 else "<f4"), dt_offsets.append(off)
        off += size
    if extra_intensity:
        fields.append(PointField(name="intensity", offset=off, datatype=7, count=1))
        dt_names.append("intensity"), dt_formats.append("<f4"), dt_offsets.append(off)
        off += 4
    step = off + 2
    rec = np.zeros(len(xyz), dtype=np.dtype({"names": dt_names, "formats": dt_formats, "offsets": dt_offsets,
                                               "itemsize": step}))
    for i, k in enumerate("xyz"):
        if k in names:
            rec[k] = xyz[:, i]
    if extra_intensity:
        rec["intensity"] = 7.0
    return PointCloud2(header=_header(store, ns, ros1), height=1, width=len(xyz), fields=fields,
                       is_bigendian=False, point_step=step, row_step=step * len(xyz),
                       data=np.frombuffer(rec.tobytes(), np.uint8), is_dense=True)


def custom_msg(store, ns, xyz, ros1):
    pkg = "livox_ros_driver" if ros1 else "livox_ros_driver2"
    Point = store.types[f"{pkg}/msg/CustomPoint"]
    Msg = store.types[f"{pkg}/msg/CustomMsg"]
    pts = [Point(offset_time=0, x=float(p[0]), y=float(p[1]), z=float(p[2]), reflectivity=7, tag=0, line=0)
           for p in xyz]
    return Msg(header=_header(store, ns, ros1), timebase=ns, point_num=len(pts), lidar_id=0,
               rsvd=np.zeros(3, np.uint8), points=pts)


def write_bag(path, frames, kind: str, *, ros1: bool, topic="/livox/lidar", extra_topics=(), extra_clouds=(),
              **kw) -> Path:
    """``kind``: "pointcloud2" or "custom".  ROS 2: an MCAP bag folder; ROS 1: a .bag file.
    ``extra_topics``: String topics beside; ``extra_clouds``: topics with the same clouds again."""
    store = _stores(ros1)
    if kind == "pointcloud2":
        msgtype = "sensor_msgs/msg/PointCloud2"
        make = lambda ns, xyz: pointcloud2(store, ns, xyz, ros1, **kw)  # noqa: E731
    else:
        msgtype = f"{'livox_ros_driver' if ros1 else 'livox_ros_driver2'}/msg/CustomMsg"
        make = lambda ns, xyz: custom_msg(store, ns, xyz, ros1)  # noqa: E731
    path = Path(path)
    if ros1:
        from rosbags.rosbag1 import Writer

        w = Writer(path)
        ser = store.serialize_ros1
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer

        w = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
        ser = store.serialize_cdr
    with w:
        conns = [w.add_connection(t, msgtype, typestore=store) for t in (topic, *extra_clouds)]
        extra = [(w.add_connection(t, "std_msgs/msg/String", typestore=store), t) for t in extra_topics]
        for ns, xyz in frames:
            for conn in conns:
                w.write(conn, ns + PERIOD_NS, ser(make(ns, xyz), msgtype))
            for c, t in extra:
                w.write(c, ns, ser(store.types["std_msgs/msg/String"](data="x"), "std_msgs/msg/String"))
    return path


def write_pcd_folder(folder, frames, names) -> Path:
    """One PCD per frame (float64 x, y, z) named like the numpy frame it came from."""
    from pypcd4 import PointCloud

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    for (ns, xyz), name in zip(frames, names):
        pc = PointCloud.from_points(np.asarray(xyz, np.float64), ("x", "y", "z"), (np.float64,) * 3)
        pc.save(folder / f"{name}.pcd")
    return folder


def write_bag_with_tf(path, frames, poses, *, ros1: bool, cloud_frame="livox", topic="/livox/lidar") -> Path:
    """A PointCloud2 bag whose clouds are in ``cloud_frame``, with ``/tf`` world -> base at each
    frame's stamp (``poses[k] = (R, t)``, points of base in world: ``R p + t``) and ``/tf_static``
    base -> livox (a fixed 0.1 m lift).  Each cloud holds ``frames[k]``'s world points seen from
    that pose, so turned back into ``world`` they are the frames again (to rounding)."""
    from scipy.spatial.transform import Rotation

    store = _stores(ros1)
    tf_type = "tf2_msgs/msg/TFMessage"
    T = store.types
    lift = np.array([0.0, 0.0, 0.1])

    def transform(ns, parent, child, R, t):
        x, y, z, w = Rotation.from_matrix(R).as_quat()
        return T["geometry_msgs/msg/TransformStamped"](
            header=_header(store, ns, ros1, parent), child_frame_id=child,
            transform=T["geometry_msgs/msg/Transform"](
                translation=T["geometry_msgs/msg/Vector3"](x=float(t[0]), y=float(t[1]), z=float(t[2])),
                rotation=T["geometry_msgs/msg/Quaternion"](x=float(x), y=float(y), z=float(z), w=float(w))))

    path = Path(path)
    if ros1:
        from rosbags.rosbag1 import Writer

        w, ser = Writer(path), store.serialize_ros1
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer

        w, ser = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP), store.serialize_cdr
    with w:
        c_cloud = w.add_connection(topic, "sensor_msgs/msg/PointCloud2", typestore=store)
        c_tf = w.add_connection("/tf", tf_type, typestore=store)
        c_static = w.add_connection("/tf_static", tf_type, typestore=store)
        ns0 = frames[0][0]
        w.write(c_static, ns0, ser(T[tf_type](transforms=[transform(ns0, "base", cloud_frame, np.eye(3), lift)]),
                                   tf_type))
        for (ns, xyz), (R, t) in zip(frames, poses):
            w.write(c_tf, ns, ser(T[tf_type](transforms=[transform(ns, "world", "base", R, t)]), tf_type))
            valid = np.any(xyz != 0, axis=1)
            local = np.zeros_like(xyz)
            local[valid] = (xyz[valid] - t) @ R - lift      # world -> base -> livox
            msg = pointcloud2(store, ns, local, ros1)
            msg.header.frame_id = cloud_frame
            w.write(c_cloud, ns + PERIOD_NS, ser(msg, "sensor_msgs/msg/PointCloud2"))
    return path
