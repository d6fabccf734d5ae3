"""Sources of recorded frames from other people's recordings: each an iterable of
``(arrival_s, Frame)`` (DESIGN.md: "Sources of recorded frames ... are all the same kind of thing").

* :mod:`~foveatrack.sources.npy_folder` -- dataset folders of ``<unix time>.npy`` frames (MMAUD)
* :mod:`~foveatrack.sources.pcd_folder` -- folders of PCD files, one per scan (``pypcd4``)
* :mod:`~foveatrack.sources.rosbag` -- ROS 1 bags and ROS 2 bags (MCAP, sqlite3) through ``rosbags``:
  ``sensor_msgs/msg/PointCloud2`` and the Livox ``CustomMsg``

:func:`open_source` picks the reader by what the path is.  Every reader raises
:class:`~foveatrack.errors.UserError` naming the file, topic, message type or field it cannot read.
"""

from __future__ import annotations

import os
from pathlib import Path

from foveatrack.errors import UserError
from foveatrack.sources.stamps import StampedFrame, frame_from_cloud, ns_from_file_stem


def open_source(path: str | os.PathLike, topic: str | None = None, rate_hz: float = 10.0,
                fixed_frame: str | None = None):
    """The frame source for ``path`` (a folder of ``.npy`` or ``.pcd`` files, a ``.bag``, a ROS 2
    bag directory or its ``.mcap`` / ``.db3`` file).  ``topic`` picks a bag's cloud topic; without
    it a bag's topics are listed in the error.  ``rate_hz``: the sensor's frame rate, for the frame
    interval ``[stamp, stamp + 1/rate_hz)`` of sources whose points carry no time of their own.
    ``fixed_frame``: a bag's clouds turned into this frame with its ``/tf`` (:mod:`foveatrack.sources.tf`)."""
    if fixed_frame is not None and not _is_bag(Path(path)):
        raise UserError(f"--fixed-frame {fixed_frame}: only a bag has /tf to take the sensor's pose from; "
                        f"{path} is not a bag")
    p = Path(path)
    if not p.exists():
        raise UserError(f"{p}: no such file or folder")
    if p.is_dir():
        if (p / "metadata.yaml").is_file():
            from foveatrack.sources.rosbag import BagSource
            return BagSource(p, topic, rate_hz, fixed_frame)
        kinds = {f.suffix.lower() for f in p.iterdir() if f.is_file()}
        if ".npy" in kinds and ".pcd" in kinds:
            raise UserError(f"{p}: holds both .npy and .pcd files; give a folder of one kind")
        if ".npy" in kinds:
            from foveatrack.sources.npy_folder import NpyFolderSource
            return NpyFolderSource(p, rate_hz)
        if ".pcd" in kinds:
            from foveatrack.sources.pcd_folder import PcdFolderSource
            return PcdFolderSource(p, rate_hz)
        _refuse_folder_of_bags(p)
        raise UserError(f"{p}: an empty folder for frames (no <unix time>.npy or .pcd files, "
                        "no ROS 2 bag metadata.yaml)")
    suffix = p.suffix.lower()
    if suffix in (".bag", ".mcap", ".db3"):
        from foveatrack.sources.rosbag import BagSource
        return BagSource(p, topic, rate_hz, fixed_frame)
    if suffix == ".pcd":
        raise UserError(f"{p}: give the folder of PCD files (one per scan, named by time), not one file")
    if suffix == ".lvx":
        raise UserError(f"{p}: a Livox Viewer file, which `track` does not read (a .bag, a ROS 2 bag folder or "
                        f".mcap/.db3, a folder of <unix time>.npy or .pcd files); `foveatrack replay {p} "
                        "--tracker-config FILE` reads Livox Viewer files")
    raise UserError(f"{p}: not a recording this reads (a .bag, a ROS 2 bag folder or .mcap/.db3, "
                    "a folder of <unix time>.npy or .pcd files)")


def _refuse_folder_of_bags(p: Path) -> None:
    """A folder with bag files and no frames (a recording split into ``rec_0.bag``, ``rec_1.bag``, ...;
    a ROS 2 bag's ``.mcap`` without its ``metadata.yaml``): ``track`` reads one bag, given itself."""
    files = sorted(f for f in p.iterdir() if f.is_file())
    for ext in (".bag", ".mcap", ".db3"):
        bags = [f for f in files if f.suffix.lower() == ext]
        if not bags:
            continue
        n = len(bags)
        names = ", ".join(f.name for f in bags[:3]) + (", ..." if n > 3 else "")
        how = (f"give one bag, e.g. {bags[0]} (`track` reads one at a time), or a ROS 2 bag folder with metadata.yaml"
               if ext == ".bag" else
               f"give the {ext} file itself, e.g. {bags[0]} (a ROS 2 bag folder has a metadata.yaml)")
        raise UserError(f"{p}: holds {n} {ext} file{'s' if n > 1 else ''} ({names}) and no <unix time>.npy or "
                        f".pcd frames: {how}")


def _is_bag(p: Path) -> bool:
    return (p / "metadata.yaml").is_file() if p.is_dir() else p.suffix.lower() in (".bag", ".mcap", ".db3")


__all__ = ["StampedFrame", "frame_from_cloud", "ns_from_file_stem", "open_source"]
