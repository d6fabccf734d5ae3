"""Livox Viewer ``.lvx`` recordings (format v1.1): reader, and a writer for fixtures and conversions.

Layout (little-endian, packed; facts: livox.md, after Livox-SDK ``sample/lidar_lvx_file``)::

    public header   24 B  signature "livox_tech" NUL-padded to 16 | version u8[4] = 1,1,0,0 | magic u32 0xAC0EA767
    private header   5 B  frame_duration u32 [ms] | device_count u8
    device info     59 B  × device_count: lidar broadcast code [16] | hub code [16] | device_index u8 |
                          device_type u8 | extrinsic_enable u8 | roll, pitch, yaw [deg], x, y, z [m] f32
    frames: header  24 B  current_offset u64 | next_offset u64 | frame_index u64
            packages      device_index u8 + one SDK v1 data packet (18-byte header + points of its type)

Points are returned as recorded, in each lidar's own frame (X forward, Y left, Z up); the device
extrinsics are available in :attr:`LvxReader.devices` but not applied.  Per-point times come from
the packet timestamps and the device type's point rate (:data:`protocol.DEVICE_POINT_RATE_HZ`).
"""

from __future__ import annotations

import os
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Iterator

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
class LvxFrame:
    frame_index: int
    points: PointBatch


class LvxReader:
    """Open an ``.lvx`` v1.1 file; UserError naming the file if it is not one.

    point_rate_hz : override the per-device point rate [points/s] (default: from the device type)
    keep_no_return : keep (0, 0, 0) points

    After :meth:`frames` has run out, ``truncated`` tells whether the last frame was cut short (it is
    skipped) and ``problem`` says where; ``counters`` holds packets, points and dropped counts.
    """

    def __init__(self, path: str | os.PathLike, point_rate_hz: float | None = None, keep_no_return: bool = False):
        self.path = Path(path)
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
        self._rate_override = point_rate_hz
        self._keep_no_return = keep_no_return
        self.truncated = False
        self.problem: str | None = None
        self.decoders: dict[int, P.DataDecoder] = {}

    def _fail(self, what: str) -> UserError:
        return UserError(f"{self.path} is not a readable Livox .lvx v1.1 file: {what}")

    def _read_headers(self) -> None:
        raw = self._fh.read(PUBLIC_HEADER.size)
        if len(raw) < PUBLIC_HEADER.size:
            raise self._fail(f"only {len(raw)} bytes, shorter than the 24-byte public header")
        sig, v0, v1, v2, v3, magic = PUBLIC_HEADER.unpack(raw)
        if sig.rstrip(b"\0") != SIGNATURE:
            hint = " (an .lvx2 / SDK2 recording?)" if sig.startswith(b"livox") else ""
            raise self._fail(f"signature {sig.rstrip(bytes(1))!r} is not 'livox_tech'{hint}")
        if magic != MAGIC:
            raise self._fail(f"magic 0x{magic:08X} is not 0xAC0EA767")
        if (v0, v1) != VERSION[:2]:
            raise self._fail(f"version {v0}.{v1}.{v2}.{v3}; only 1.1 is supported")
        raw = self._fh.read(PRIVATE_HEADER.size)
        if len(raw) < PRIVATE_HEADER.size:
            raise self._fail("cut short in the private header")
        self.frame_duration_ms, n_dev = PRIVATE_HEADER.unpack(raw)
        self.devices: list[LvxDevice] = []
        for k in range(n_dev):
            raw = self._fh.read(DEVICE_INFO.size)
            if len(raw) < DEVICE_INFO.size:
                raise self._fail(f"cut short in device info {k} of {n_dev}")
            lc, hc, idx, dtype, ext, *pose = DEVICE_INFO.unpack(raw)
            self.devices.append(
                LvxDevice(lc.split(b"\0")[0].decode("ascii", "replace"), hc.split(b"\0")[0].decode("ascii", "replace"),
                          idx, dtype, bool(ext), *pose)
            )
        self.data_offset = self._fh.tell()

    def _decoder(self, device_index: int) -> P.DataDecoder:
        dec = self.decoders.get(device_index)
        if dec is None:
            dtype = next((d.device_type for d in self.devices if d.device_index == device_index), None)
            rate = self._rate_override or P.DEVICE_POINT_RATE_HZ.get(dtype, 240_000)
            dec = self.decoders[device_index] = P.DataDecoder(float(rate), self._keep_no_return)
        return dec

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
            if cur != pos or nxt <= cur + FRAME_HEADER.size - 1:
                raise self._fail(f"frame at byte {pos} has offsets current={cur} next={nxt} (corrupt)")
            if nxt > self.size:
                self._cut(pos, f"frame {index}")
                return
            body = fh.read(nxt - pos - FRAME_HEADER.size)
            yield LvxFrame(index, self._decode_body(body, pos + FRAME_HEADER.size, index))
            pos = nxt

    def _cut(self, pos: int, what: str) -> None:
        self.truncated = True
        self.problem = f"{self.path}: file cut short in {what} at byte {pos} of {self.size}; earlier frames are complete"

    def _decode_body(self, body: bytes, base: int, index: int) -> PointBatch:
        per_dev: dict[int, list[bytes]] = {}
        off, n = 0, len(body)
        while off < n:
            if n - off < 1 + P.HEADER_LEN:
                raise self._fail(f"frame {index}: package at byte {base + off} is cut short")
            dev = body[off]
            dt = body[off + 1 + 9]
            if dt not in P.PACKET_LEN:
                raise self._fail(f"frame {index}: package at byte {base + off} has unknown data type {dt}")
            end = off + 1 + P.PACKET_LEN[dt]
            if end > n:
                raise self._fail(f"frame {index}: package at byte {base + off} overruns the frame")
            per_dev.setdefault(dev, []).append(body[off + 1 : end])
            off = end
        return PointBatch.concat([b for dev, pk in per_dev.items() for b in self._decoder(dev).decode(pk)])

    @property
    def counters(self) -> dict:
        out: dict = {}
        for dec in self.decoders.values():
            for k, v in dec.counters.items():
                out[k] = out.get(k, 0) + v
            for k, v in dec.dropped.items():
                out[f"dropped_{k}"] = out.get(f"dropped_{k}", 0) + v
        return out

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


def write_lvx(
    path: str | os.PathLike,
    frames: Iterable[Iterable[tuple[int, bytes]]],
    devices: Iterable[LvxDevice],
    frame_duration_ms: int = 50,
) -> None:
    """Write an ``.lvx`` v1.1 file: ``frames`` is an iterable of frames, each of (device_index, packet)."""
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
