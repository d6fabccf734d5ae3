"""Livox Viewer ``.lvx`` recordings (format v1.1): reader, and a writer for exports and fixtures.

Layout (little-endian, packed; facts: livox.md, after Livox-SDK 2.3.0 ``sample/lidar_lvx_file``)::

    public header   24 B  signature "livox_tech" NUL-padded to 16 | version u8[4] = 1,1,0,0 | magic u32 0xAC0EA767
    private header   5 B  frame_duration u32 [ms] | device_count u8
    device info     59 B  × device_count: lidar broadcast code [16] | hub code [16] | device_index u8 |
                          device_type u8 | extrinsic_enable u8 | roll, pitch, yaw [deg], x, y, z [m] f32
    frames: header  24 B  current_offset u64 | next_offset u64 | frame_index u64
            packages      device_index u8 + one SDK v1 data packet (18-byte header + points of its type)

Package header (the SDK's ``LvxBasePackDetail`` without its in-memory ``pack_size``), offsets from
the package's first byte: device_index +0 | version +1 (= 5) | slot +2 | id +3 | reserved +4 |
err_code +5 u32 | timestamp_type +9 | data_type +10 | timestamp +11 (8 bytes).

Data types 0-8 are read (SDK 2.3.0 ``livox_def.h``): 0-5, 7, 8 carry points (dual and triple
returns come out slot by slot, every return of a slot at the slot's time), 6 carries one IMU sample
(gyro rad/s, acc g) that goes to its own stream (:attr:`LvxFrame.imu`).

Points are returned as recorded, in each lidar's own frame (X forward, Y left, Z up); the device
extrinsics are available in :attr:`LvxReader.devices` but not applied.  Per-point times come from
the packet timestamps and the device type's point rate (:data:`protocol.DEVICE_POINT_RATE_HZ`).

A file that is not LVX v1.1, a frame whose offsets do not chain, or a package with a bad field
(device index, version, data type, timestamp type or date, length) is refused with a
:class:`~foveatrack.errors.UserError` naming the file, the byte offset and the field.  Only a file
cut short inside its last frame is read up to its last complete frame (``truncated``/``problem``).
"""

from __future__ import annotations

import os
import struct
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Iterator

import numpy as np

from foveatrack.errors import UserError
from foveatrack.livox import protocol as P
from foveatrack.livox.protocol import PointBatch

SIGNATURE = b"livox_tech"
VERSION = (1, 1, 0, 0)
MAGIC = 0xAC0EA767
PUBLIC_HEADER = struct.Struct("<16s4BI")
PRIVATE_HEADER = struct.Struct("<IB")
DEVICE_INFO = struct.Struct("<16s16sBBB6f")
FRAME_HEADER = struct.Struct("<QQQ")
assert (PUBLIC_HEADER.size, PRIVATE_HEADER.size, DEVICE_INFO.size, FRAME_HEADER.size) == (24, 5, 59, 24)

IMU_DTYPE = P.POINT_DTYPES[P.IMU_DATA_TYPE]   # gyro_x..z [rad/s], acc_x..z [g], f32 each
PACKAGE_HEADER_LEN = 1 + P.HEADER_LEN           # device_index + the SDK data-packet header
TIMESTAMP_TYPE_UTC = P.TIMESTAMP_TYPE_UTC
TIMESTAMP_TYPES = (*P.TIMESTAMP_TYPES_NS, TIMESTAMP_TYPE_UTC)


def decode_imu(payload: bytes) -> tuple[float, float, float, float, float, float]:
    """One SDK v1 IMU sample (the 24 bytes after a type-6 packet header): gyro x, y, z [rad/s],
    acc x, y, z [g] (``LivoxImuPoint``, SDK 2.3.0 ``livox_def.h``)."""
    if len(payload) < IMU_DTYPE.itemsize:
        raise P.PacketError("data_truncated", f"IMU payload {len(payload)} bytes < {IMU_DTYPE.itemsize}")
    return struct.unpack_from("<6f", payload)


@dataclass(frozen=True)
class LvxDevice:
    lidar_code: str
    hub_code: str
    device_index: int
    device_type: int
    extrinsic_enable: bool
    roll_deg: float
    pitch_deg: float
    yaw_deg: float
    x_m: float
    y_m: float
    z_m: float


@dataclass(frozen=True, eq=False)
class ImuBatch:
    """IMU samples.  t_ns (n,) int64 [ns] packet time; gyro_rad_s, acc_g (n, 3) float64 (the f32
    values widened); device_index (n,) uint8."""

    t_ns: np.ndarray
    gyro_rad_s: np.ndarray
    acc_g: np.ndarray
    device_index: np.ndarray

    def __len__(self) -> int:
        return int(self.t_ns.shape[0])

    @staticmethod
    def from_packets(arr: np.ndarray, device_index: int) -> "ImuBatch":
        pts = arr["pts"][:, 0]
        g = np.stack([pts["gyro_x"], pts["gyro_y"], pts["gyro_z"]], axis=-1).astype(np.float64)
        a = np.stack([pts["acc_x"], pts["acc_y"], pts["acc_z"]], axis=-1).astype(np.float64)
        return ImuBatch(arr["hdr"]["timestamp"].astype(np.int64), g, a, np.full(arr.shape[0], device_index, np.uint8))

    @staticmethod
    def concat(batches: list["ImuBatch"]) -> "ImuBatch | None":
        if not batches:
            return None
        return ImuBatch(*(np.concatenate([getattr(b, k) for b in batches])
                          for k in ("t_ns", "gyro_rad_s", "acc_g", "device_index")))


@dataclass(frozen=True, eq=False)
class LvxFrame:
    """One recorded frame: its points (device by device, file order within a device;
    ``point_device`` gives each point's device index) and its IMU samples (None if it has none)."""

    frame_index: int
    points: PointBatch
    imu: ImuBatch | None = None
    point_device: np.ndarray | None = None


class LvxReader:
    """Open an ``.lvx`` v1.1 file; UserError naming the file if it is not one.

    point_rate_hz : override the per-device point rate [points/s] (default: from the device type)
    keep_no_return : keep (0, 0, 0) points

    After :meth:`frames` has run out, ``truncated`` tells whether the last frame was cut short (it is
    skipped) and ``problem`` says where; ``counters`` holds packets, points, no_return_points and
    imu_packets.
    """

    def __init__(self, path: str | os.PathLike, point_rate_hz: float | None = None, keep_no_return: bool = False):
        self.path = Path(path)
        if point_rate_hz is not None and not point_rate_hz > 0:
            raise UserError(f"point rate must be > 0 points/s, got {point_rate_hz!r}")
        try:
            self._fh = open(self.path, "rb")
        except OSError as exc:
            raise UserError(f"cannot open Livox recording {self.path}: {exc.strerror}") from None
        self.size = self.path.stat().st_size
        try:
            self._read_headers()
        except BaseException:
            self._fh.close()
            raise
        self._keep_no_return = keep_no_return
        self.truncated = False
        self.problem: str | None = None
        self.counters: Counter = Counter()
        self._rates = {d.device_index: float(point_rate_hz or P.DEVICE_POINT_RATE_HZ.get(d.device_type, 240_000))
                       for d in self.devices}

    def _fail(self, what: str) -> UserError:
        return UserError(f"{self.path} is not a readable Livox .lvx v1.1 file: {what}")

    def _read_headers(self) -> None:
        raw = self._fh.read(PUBLIC_HEADER.size)
        if len(raw) < PUBLIC_HEADER.size:
            raise self._fail(f"only {len(raw)} bytes, shorter than the 24-byte public header")
        sig, v0, v1, v2, v3, magic = PUBLIC_HEADER.unpack(raw)
        if sig.rstrip(b"\0") != SIGNATURE:
            hint = " (an .lvx2 / SDK2 recording?)" if sig.startswith(b"livox") else ""
            raise self._fail(f"byte 0, field signature: {sig.rstrip(bytes(1))!r} is not 'livox_tech'{hint}")
        if magic != MAGIC:
            raise self._fail(f"byte 20, field magic_code: 0x{magic:08X} is not 0xAC0EA767")
        if (v0, v1) != VERSION[:2]:
            raise self._fail(f"byte 16, field version: {v0}.{v1}.{v2}.{v3}; only 1.1 is supported")
        raw = self._fh.read(PRIVATE_HEADER.size)
        if len(raw) < PRIVATE_HEADER.size:
            raise self._fail("cut short in the private header (bytes 24-28)")
        self.frame_duration_ms, n_dev = PRIVATE_HEADER.unpack(raw)
        self.devices: list[LvxDevice] = []
        for k in range(n_dev):
            at = self._fh.tell()
            raw = self._fh.read(DEVICE_INFO.size)
            if len(raw) < DEVICE_INFO.size:
                raise self._fail(f"cut short in device info {k} of {n_dev} (byte {at})")
            lc, hc, idx, dtype, ext, *pose = DEVICE_INFO.unpack(raw)
            if any(d.device_index == idx for d in self.devices):
                raise self._fail(f"device info {k} at byte {at}, field device_index: {idx} is used twice")
            self.devices.append(
                LvxDevice(lc.split(b"\0")[0].decode("ascii", "replace"), hc.split(b"\0")[0].decode("ascii", "replace"),
                          idx, dtype, bool(ext), *pose)
            )
        self.data_offset = self._fh.tell()

    def frames(self) -> Iterator[LvxFrame]:
        """The frames in file order (a frame cut short at the end of the file is skipped)."""
        fh = self._fh
        fh.seek(self.data_offset)
        pos = self.data_offset
        while pos < self.size:
            raw = fh.read(FRAME_HEADER.size)
            if len(raw) < FRAME_HEADER.size:
                self._cut(pos, "frame header")
                return
            cur, nxt, index = FRAME_HEADER.unpack(raw)
            if cur != pos:
                raise self._fail(f"frame header at byte {pos}, field current_offset: {cur}, not the frame's own "
                                 f"offset {pos} (offsets corrupt)")
            if nxt < cur + FRAME_HEADER.size:
                raise self._fail(f"frame header at byte {pos}, field next_offset: {nxt} is before the end of the "
                                 f"frame header ({cur + FRAME_HEADER.size}) (offsets corrupt)")
            if nxt > self.size:
                self._cut(pos, f"frame {index}")
                return
            body = fh.read(nxt - pos - FRAME_HEADER.size)
            yield self._decode_body(body, pos + FRAME_HEADER.size, index)
            pos = nxt

    def _cut(self, pos: int, what: str) -> None:
        self.truncated = True
        self.problem = f"{self.path}: file cut short in {what} at byte {pos} of {self.size}; earlier frames are complete"

    def _package_error(self, index: int, at: int, what: str) -> UserError:
        return self._fail(f"frame {index}, package at byte {at}: {what}")

    def _check_packages(self, body: bytes, base: int, index: int) -> list[tuple[int, int, list[int]]]:
        """Every package of a frame checked field by field; runs of consecutive packages of one
        device and data type as (device, data_type, offsets in body)."""
        runs: list[tuple[int, int, list[int]]] = []
        off, n = 0, len(body)
        while off < n:
            at = base + off
            if n - off < PACKAGE_HEADER_LEN:
                raise self._package_error(index, at, f"cut short: {n - off} bytes left in the frame, a package "
                                                     f"header is {PACKAGE_HEADER_LEN}")
            dev, ver, ts_type, dt = body[off], body[off + 1], body[off + 9], body[off + 10]
            if dev not in self._rates:
                raise self._package_error(index, at, f"field device_index (byte {at}) = {dev}, not one of the "
                                                     f"file's devices {sorted(self._rates)}")
            if ver != P.DATA_VERSION:
                raise self._package_error(index, at, f"field version (byte {at + 1}) = {ver}, expected "
                                                     f"{P.DATA_VERSION} (Livox SDK v1 data packet)")
            if dt not in P.PACKET_LEN:
                raise self._package_error(index, at, f"field data_type (byte {at + 10}) = {dt}: unknown data type "
                                                     f"{dt} (0-8 are defined)")
            if ts_type not in TIMESTAMP_TYPES:
                raise self._package_error(index, at, f"field timestamp_type (byte {at + 9}) = {ts_type}, expected "
                                                     f"one of {list(TIMESTAMP_TYPES)}")
            end = off + 1 + P.PACKET_LEN[dt]
            if end > n:
                raise self._package_error(index, at, f"data_type {dt} needs {P.PACKET_LEN[dt] + 1} bytes, the "
                                                     f"frame has {n - off} left (overruns the frame)")
            if ts_type != TIMESTAMP_TYPE_UTC:
                ts = int.from_bytes(body[off + 11:off + 19], "little")
                if ts >= P.MAX_TIMESTAMP_NS:
                    raise self._package_error(index, at, f"field timestamp (byte {at + 11}) = 0x{ts:016x} ns, beyond "
                                                         f"any sensor clock (>= 2^62 ns)")
            if ts_type == TIMESTAMP_TYPE_UTC:
                try:
                    P._utc_ns(np.frombuffer(body, np.uint8, 8, off + 11)[None, :])
                except (ValueError, OverflowError) as exc:
                    raise self._package_error(index, at, f"field timestamp (byte {at + 11}) is not a valid UTC "
                                                         f"date: {exc}") from None
            if runs and runs[-1][0] == dev and runs[-1][1] == dt:
                runs[-1][2].append(off)
            else:
                runs.append((dev, dt, [off]))
            off = end
        return runs

    def _decode_body(self, body: bytes, base: int, index: int) -> LvxFrame:
        by_dev: dict[int, list[PointBatch]] = {}
        imu: list[ImuBatch] = []
        for dev, dt, offs in self._check_packages(body, base, index):
            L = P.PACKET_LEN[dt]
            arr = np.frombuffer(b"".join(body[o + 1 : o + 1 + L] for o in offs), dtype=P.packet_dtype(dt))
            if dt == P.IMU_DATA_TYPE:
                imu.append(ImuBatch.from_packets(arr, dev))
                self.counters["imu_packets"] += len(offs)
                continue
            b, removed = P.decode_packets_array(arr, self._rates[dev], self._keep_no_return)
            self.counters["packets"] += len(offs)
            self.counters["points"] += len(b)
            self.counters["no_return_points"] += removed
            by_dev.setdefault(dev, []).append(b)
        batches = [b for bs in by_dev.values() for b in bs]
        point_device = np.concatenate([np.full(len(b), dev, np.uint8) for dev, bs in by_dev.items() for b in bs]
                                      or [np.zeros(0, np.uint8)])
        return LvxFrame(index, PointBatch.concat(batches), ImuBatch.concat(imu), point_device)

    def close(self) -> None:
        self._fh.close()

    def __enter__(self) -> "LvxReader":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def read_lvx(path: str | os.PathLike, point_rate_hz: float | None = None, keep_no_return: bool = False) -> Iterator[PointBatch]:
    """Iterate the point batches of an ``.lvx`` v1.1 file, one per recorded frame (50 ms by default)."""
    with LvxReader(path, point_rate_hz, keep_no_return) as r:
        for f in r.frames():
            yield f.points


def read_lvx_imu(path: str | os.PathLike) -> ImuBatch | None:
    """All IMU samples (data type 6) of an ``.lvx`` file, in file order; None if it has none."""
    with LvxReader(path) as r:
        return ImuBatch.concat([f.imu for f in r.frames() if f.imu is not None])


def write_lvx(
    path: str | os.PathLike,
    frames: Iterable[Iterable[tuple[int, bytes]]],
    devices: Iterable[LvxDevice],
    frame_duration_ms: int = 50,
) -> None:
    """Write an ``.lvx`` v1.1 file: ``frames`` is an iterable of frames, each of (device_index, packet).

    Byte for byte the layout the SDK's ``lidar_lvx_sample`` writes (``LvxFileHandle``)."""
    devices = list(devices)
    with open(path, "wb") as fh:
        fh.write(PUBLIC_HEADER.pack(SIGNATURE.ljust(16, b"\0"), *VERSION, MAGIC))
        fh.write(PRIVATE_HEADER.pack(frame_duration_ms, len(devices)))
        for d in devices:
            fh.write(DEVICE_INFO.pack(d.lidar_code.encode().ljust(16, b"\0"), d.hub_code.encode().ljust(16, b"\0"),
                                      d.device_index, d.device_type, int(d.extrinsic_enable),
                                      d.roll_deg, d.pitch_deg, d.yaw_deg, d.x_m, d.y_m, d.z_m))
        for k, frame in enumerate(frames):
            body = b"".join(bytes((dev,)) + pk for dev, pk in frame)
            cur = fh.tell()
            fh.write(FRAME_HEADER.pack(cur, cur + FRAME_HEADER.size + len(body), k))
            fh.write(body)
