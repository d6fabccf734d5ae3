"""Livox SDK v1 wire protocol: control frames and point-cloud data packets.  Pure bytes, no I/O.

Everything here is little-endian and packed, as in the SDK's ``#pragma pack(1)`` structs.

Control frames (UDP, command port 65000 on the lidar, broadcast to host port 55000)::

    sof u8 = 0xAA | version u8 = 1 | length u16 (whole frame) | cmd_type u8 (0 CMD, 1 ACK, 2 MSG)
    | seq u16 | crc16 u16 over the 7 bytes before it | cmd_set u8 | cmd_id u8 | payload | crc32 u32
    over everything before it

CRC variants (read in Livox-SDK/Livox-SDK, ``sdk_core/src/comm/sdk_protocol.cpp`` and
``sdk_core/src/third_party/FastCRC/FastCRCsw.cpp``, SDK 2.3.0):

- header: CRC-16/MCRF4XX (reflected poly 0x1021 = 0x8408, no final xor) with the *register*
  initialised to 0x4C49 (tools that take a non-reflected init spell it 0x9232).  The check over the
  9 header bytes including the stored CRC is 0.
- frame: the standard reflected CRC-32 (zlib's) with seed 0x564F580A, i.e.
  ``zlib.crc32(buf, 0x564F580A)`` (FastCRC xors the seed with 0xFFFFFFFF in and out, as zlib does).

Data packets (UDP, from the lidar to the host's data port): an 18-byte header then the points::

    version u8 = 5 | slot u8 | id u8 | reserved u8 | err_code u32 | timestamp_type u8 | data_type u8
    | timestamp 8 bytes (u64 ns for types 0 no-sync, 1 PTP, 4 PPS; UTC bytes for 3 PPS+GPS)

Point layouts (``POINT_DTYPES``): 0 Cartesian (x, y, z i32 mm; reflectivity u8) × 100, 1 spherical
(depth u32 mm; zenith, azimuth u16 in 0.01 deg; reflectivity u8) × 100, 2 extended Cartesian (type 0 +
tag u8) × 96, 3 extended spherical (type 1 + tag) × 96, 4 dual Cartesian (2 × (x, y, z, refl, tag)) ×
48, 5 dual extended spherical (zenith, azimuth u16 shared; 2 × (depth u32, refl, tag)) × 48, 6 IMU
(6 × f32) × 1, 7 triple extended Cartesian (3 × (x, y, z, refl, tag)) × 30, 8 triple extended
spherical (zenith, azimuth; 3 × (depth, refl, tag)) × 30 (SDK 2.3.0 ``livox_def.h``).  Points decode to metres in the lidar frame: X forward (optical axis), Y left,
Z up, right-handed; spherical :math:`x = r\\sin\\theta\\cos\\varphi`, :math:`y = r\\sin\\theta
\\sin\\varphi`, :math:`z = r\\cos\\theta` (θ zenith from +Z, φ azimuth from +X towards +Y).
A point (0, 0, 0) (depth 0) is "no return".

Per-point time: the packet timestamp is the time of its first point; point ``i`` of a packet is at
``timestamp + round(i * 1e9 / point_rate_hz)`` ns (the dual- and triple-return types give every
return of a slot the same time; returns come out slot by slot, first return first).

Decoding is done with numpy structured dtypes over many packets at once (no per-point Python loop).
:class:`DataDecoder` is the safe entry point: every malformed datagram is dropped and counted under a
reason in ``DATA_DROP_REASONS``; nothing it is fed can make it raise.  :func:`parse_control_safe`
does the same for control frames (``CTRL_DROP_REASONS``).
"""

from __future__ import annotations

import datetime as _dt
import ipaddress
import struct
import zlib
from collections import Counter, deque
from dataclasses import dataclass, field
from typing import Iterable, Sequence

import numpy as np

from foveatrack.errors import UserError

# --------------------------------------------------------------------------------------------
# constants

SOF = 0xAA
CTRL_VERSION = 1
DATA_VERSION = 5

CMD_TYPE_CMD = 0
CMD_TYPE_ACK = 1
CMD_TYPE_MSG = 2
CMD_TYPES = (CMD_TYPE_CMD, CMD_TYPE_ACK, CMD_TYPE_MSG)

CMD_SET_GENERAL = 0
CMD_SET_LIDAR = 1
CMD_SET_HUB = 2

# general command set (SDK 2.3.0 ``command_impl.h``)
CMD_ID_BROADCAST = 0
CMD_ID_HANDSHAKE = 1
CMD_ID_QUERY_INFO = 2
CMD_ID_HEARTBEAT = 3
CMD_ID_SAMPLING = 4
CMD_ID_COORDINATE_SYSTEM = 5
CMD_ID_DISCONNECT = 6
CMD_ID_PUSH_ABNORMAL_STATE = 7
CMD_ID_SET_IP = 8
CMD_ID_GET_IP = 9
CMD_ID_REBOOT = 0x0A
CMD_ID_WRITE_PARAMS = 0x0B
CMD_ID_READ_PARAMS = 0x0C
CMD_ID_RESET_PARAMS = 0x0D

# lidar command set
LIDAR_ID_SET_MODE = 0
LIDAR_ID_WRITE_EXTRINSIC = 1
LIDAR_ID_READ_EXTRINSIC = 2
LIDAR_ID_RAIN_FOG = 3
LIDAR_ID_SET_FAN = 4
LIDAR_ID_GET_FAN = 5
LIDAR_ID_SET_RETURN_MODE = 6
LIDAR_ID_GET_RETURN_MODE = 7
LIDAR_ID_SET_IMU_FREQ = 8
LIDAR_ID_GET_IMU_FREQ = 9
LIDAR_ID_SET_UTC = 0x0A

#: ACK return codes: the v1 protocol defines 0 success and 1 fail for every command, and 2
#: "switching" for lidar set mode; there is no separate "not supported" code.
RET_SUCCESS = 0
RET_FAIL = 1
RET_SWITCHING = 2

#: Work states of the heartbeat ACK (``LidarState``); modes of lidar set mode (``LidarMode``).
LIDAR_STATES = {0: "init", 1: "normal", 2: "power-saving", 3: "standby", 4: "error", 5: "unknown"}
LIDAR_MODE_NORMAL, LIDAR_MODE_POWER_SAVING, LIDAR_MODE_STANDBY = 1, 2, 3
#: Return modes (``PointCloudReturnMode``) and IMU push frequencies (``ImuFreq``).
RETURN_MODES = {0: "first", 1: "strongest", 2: "dual", 3: "triple"}
IMU_FREQ_OFF, IMU_FREQ_200HZ = 0, 1
IMU_RATE_HZ = 200.0
#: Configuration parameter keys (general 0x0B/0x0C) and their error codes (``KeyErrorCode``).
PARAM_KEY_HIGH_SENSITIVITY, PARAM_KEY_SCAN_PATTERN, PARAM_KEY_SLOT_NUM = 1, 2, 3
KEY_NO_ERROR, KEY_NOT_SUPPORTED, KEY_EXEC_FAILED, KEY_VALUE_ERROR, KEY_VALUE_LENGTH_ERROR = 0, 1, 2, 4, 5

DEFAULT_BROADCAST_PORT = 55000
DEFAULT_SENSOR_CMD_PORT = 65000
BROADCAST_CODE_LEN = 16      # the field; the code itself is NUL-terminated, 15 characters at most
BROADCAST_CODE_MAX_CHARS = 15
SERIAL_LEN = 14              # a real code is the 14-character serial + one digit (1; 1/2/3 on a Mid-100)

DEVICE_TYPES = {"hub": 0, "mid40": 1, "tele15": 2, "horizon": 3, "mid70": 6, "avia": 7}
#: Nominal single-return point rates by device type [points/s] (facts: livox.md spec table).
DEVICE_POINT_RATE_HZ = {0: 100_000, 1: 100_000, 2: 240_000, 3: 240_000, 6: 100_000, 7: 240_000}

CRC16_INIT = 0x4C49
CRC32_SEED = 0x564F580A

CTRL_HEADER_LEN = 9  # sof .. crc16
CTRL_MIN_LEN = CTRL_HEADER_LEN + 2 + 4  # + cmd_set, cmd_id + crc32
CTRL_MAX_LEN = 1400

CTRL_DROP_REASONS = (
    "ctrl_too_short",
    "ctrl_bad_sof",
    "ctrl_bad_version",
    "ctrl_bad_header_crc",
    "ctrl_truncated",
    "ctrl_oversize",
    "ctrl_bad_crc32",
    "ctrl_unknown_cmd_type",
)

DATA_DROP_REASONS = (
    "data_truncated_header",
    "data_bad_version",
    "data_unknown_type",
    "data_unknown_timestamp_type",
    "data_bad_timestamp",
    "data_truncated",
    "data_oversize",
)


class PacketError(UserError):
    """A datagram is not a valid Livox SDK v1 frame/packet.  ``reason`` is one of the drop reasons."""

    def __init__(self, reason: str, detail: str = ""):
        self.reason = reason
        super().__init__(f"bad Livox packet ({reason}){': ' + detail if detail else ''}")


# --------------------------------------------------------------------------------------------
# CRCs


def _make_crc16_table() -> list[int]:
    table = []
    for b in range(256):
        crc = b
        for _ in range(8):
            crc = (crc >> 1) ^ 0x8408 if crc & 1 else crc >> 1
        table.append(crc)
    return table


_CRC16_TABLE = _make_crc16_table()


def crc16_mcrf4xx(data: bytes, init: int = CRC16_INIT) -> int:
    """CRC-16/MCRF4XX (reflected 0x1021, no xorout) with the register starting at ``init``."""
    crc = init
    for b in data:
        crc = (crc >> 8) ^ _CRC16_TABLE[(crc ^ b) & 0xFF]
    return crc


def crc32_livox(data: bytes) -> int:
    """The SDK's frame CRC-32: zlib's CRC-32 seeded with 0x564F580A."""
    return zlib.crc32(data, CRC32_SEED) & 0xFFFFFFFF


# --------------------------------------------------------------------------------------------
# control frames


@dataclass(frozen=True)
class ControlFrame:
    """One SDK v1 control frame.  ``cmd_type`` 0 CMD, 1 ACK, 2 MSG; ``seq`` 0..65535."""

    cmd_type: int
    seq: int
    cmd_set: int
    cmd_id: int
    payload: bytes = b""

    @property
    def key(self) -> tuple[int, int]:
        return (self.cmd_set, self.cmd_id)


def encode_control(frame: ControlFrame) -> bytes:
    """Serialise a control frame (header CRC16 and frame CRC32 filled in)."""
    length = CTRL_MIN_LEN + len(frame.payload)
    if length > CTRL_MAX_LEN:
        raise ValueError(f"control payload too long ({len(frame.payload)} bytes)")
    pre = struct.pack("<BBHBH", SOF, CTRL_VERSION, length, frame.cmd_type, frame.seq & 0xFFFF)
    body = pre + struct.pack("<H", crc16_mcrf4xx(pre)) + bytes((frame.cmd_set, frame.cmd_id)) + frame.payload
    return body + struct.pack("<I", crc32_livox(body))


def parse_control(buf: bytes) -> ControlFrame:
    """Parse one control datagram; raises :class:`PacketError` with a reason from CTRL_DROP_REASONS."""
    n = len(buf)
    if n < CTRL_HEADER_LEN:
        raise PacketError("ctrl_too_short", f"{n} bytes < {CTRL_HEADER_LEN}")
    if buf[0] != SOF:
        raise PacketError("ctrl_bad_sof", f"0x{buf[0]:02X} != 0xAA")
    if buf[1] != CTRL_VERSION:
        raise PacketError("ctrl_bad_version", f"version {buf[1]} != {CTRL_VERSION}")
    if crc16_mcrf4xx(bytes(buf[:CTRL_HEADER_LEN])) != 0:
        raise PacketError("ctrl_bad_header_crc")
    (length,) = struct.unpack_from("<H", buf, 2)
    if length < CTRL_MIN_LEN:
        raise PacketError("ctrl_too_short", f"length field {length} < {CTRL_MIN_LEN}")
    if n < length:
        raise PacketError("ctrl_truncated", f"{n} bytes < length field {length}")
    if n > length:
        raise PacketError("ctrl_oversize", f"{n} bytes > length field {length}")
    (crc,) = struct.unpack_from("<I", buf, length - 4)
    if crc32_livox(bytes(buf[: length - 4])) != crc:
        raise PacketError("ctrl_bad_crc32")
    cmd_type = buf[4]
    if cmd_type not in CMD_TYPES:
        raise PacketError("ctrl_unknown_cmd_type", f"cmd_type {cmd_type}")
    (seq,) = struct.unpack_from("<H", buf, 5)
    return ControlFrame(cmd_type, seq, buf[9], buf[10], bytes(buf[11 : length - 4]))


def parse_control_safe(buf: bytes) -> tuple[ControlFrame | None, str | None]:
    """Like :func:`parse_control` but never raises: ``(frame, None)`` or ``(None, reason)``."""
    try:
        return parse_control(buf), None
    except PacketError as exc:
        return None, exc.reason
    except Exception:  # pragma: no cover - defensive: a bug must not kill the receive loop
        return None, "ctrl_too_short"


# -- payloads of the general command set


def check_broadcast_code(code: str) -> str:
    """A broadcast code as the SDK can hold it: 1-15 printable ASCII characters (the 16-byte field
    keeps a NUL: ``livox_def.h`` "null-terminated string, 15 characters at most").  Raises UserError."""
    if not isinstance(code, str) or not 1 <= len(code) <= BROADCAST_CODE_MAX_CHARS or not code.isascii() \
            or not code.isprintable():
        raise UserError(f"Livox broadcast code {code!r} must be 1-{BROADCAST_CODE_MAX_CHARS} printable ASCII "
                        "characters (the SDK's 16-byte field is NUL-terminated); real units use the 14-character "
                        "serial number and one digit, e.g. 0TFDFCE00504061")
    return code


def make_broadcast_code(serial: str, index: int = 1) -> str:
    """The code a real unit broadcasts: its 14-character serial and one digit (1; a Mid-100's three
    units 1, 2, 3 for left, middle, right; SDK README, "Broadcast Code")."""
    if len(serial) != SERIAL_LEN or not serial.isascii() or not serial.isalnum():
        raise UserError(f"Livox serial {serial!r} must be {SERIAL_LEN} ASCII letters or digits")
    if not 1 <= index <= 9:
        raise UserError(f"Livox broadcast code digit must be 1..9, got {index}")
    return serial + str(index)


def broadcast_payload(broadcast_code: str, dev_type: int) -> bytes:
    code = check_broadcast_code(broadcast_code).encode("ascii").ljust(BROADCAST_CODE_LEN, b"\0")
    return code + struct.pack("<BH", dev_type, 0)


def parse_broadcast(payload: bytes) -> tuple[str, int]:
    """``(broadcast_code, dev_type)`` of a broadcast message payload."""
    if len(payload) < BROADCAST_CODE_LEN + 1:
        raise PacketError("ctrl_truncated", "broadcast payload too short")
    code = payload[:BROADCAST_CODE_LEN].split(b"\0", 1)[0].decode("ascii", "replace")
    return code, payload[BROADCAST_CODE_LEN]


def handshake_payload(host_ip: str, data_port: int, cmd_port: int, imu_port: int = 0) -> bytes:
    """Handshake request: host IP (octets in network order), data, command and IMU ports."""
    return ipaddress.IPv4Address(host_ip).packed + struct.pack("<HHH", data_port, cmd_port, imu_port)


def parse_handshake(payload: bytes) -> tuple[str, int, int, int]:
    """``(host_ip, data_port, cmd_port, imu_port)``; accepts the 8-byte SDK 2.3 form (imu_port 0)."""
    if len(payload) < 8:
        raise PacketError("ctrl_truncated", "handshake payload too short")
    ip = str(ipaddress.IPv4Address(bytes(payload[:4])))
    data_port, cmd_port = struct.unpack_from("<HH", payload, 4)
    imu_port = struct.unpack_from("<H", payload, 8)[0] if len(payload) >= 10 else 0
    return ip, data_port, cmd_port, imu_port


def heartbeat_ack_payload(ret_code: int = 0, state: int = 1, feature: int = 0, status: int = 0) -> bytes:
    """Heartbeat ACK: ret_code, work state (1 normal), feature, status bits u32."""
    return struct.pack("<BBBI", ret_code, state, feature, status)


def parse_heartbeat_ack(payload: bytes) -> tuple[int, int, int, int]:
    """``(ret_code, work_state, feature, status)`` of a heartbeat ACK (``HeartbeatResponse``); status is
    the init progress (0-100) in state 0, else the status code bits (:func:`decode_status_code`)."""
    if len(payload) < 7:
        raise PacketError("ctrl_truncated", f"heartbeat ACK payload {len(payload)} bytes < 7")
    ret, state, feature, status = struct.unpack_from("<BBBI", payload)
    return ret, state, feature, status


def device_info_payload(firmware: Sequence[int], ret: int = RET_SUCCESS) -> bytes:
    """Query-device-information ACK: ret_code, firmware version AA.BB.CC.DD as 4 bytes."""
    return bytes((ret, *firmware))


def parse_device_info(payload: bytes) -> tuple[int, tuple[int, int, int, int]]:
    """``(ret_code, (AA, BB, CC, DD))`` of a device-information ACK."""
    if len(payload) < 5:
        raise PacketError("ctrl_truncated", f"device information ACK payload {len(payload)} bytes < 5")
    return payload[0], tuple(payload[1:5])


def firmware_str(fw: Sequence[int]) -> str:
    """Firmware as Livox writes it, e.g. (3, 8, 0, 0) -> '03.08.0000'."""
    return f"{fw[0]:02d}.{fw[1]:02d}.{fw[2]:02d}{fw[3]:02d}"


#: LiDAR status code bits (``LidarErrorCode``, the err_code of data packets and heartbeat ACKs):
#: name -> (first bit, width).  system_status: 0 normal, 1 warning, 2 error.
STATUS_FIELDS = {
    "temp_status": (0, 2), "volt_status": (2, 2), "motor_status": (4, 2), "dirty_warn": (6, 2),
    "firmware_err": (8, 1), "pps_status": (9, 1), "device_status": (10, 1), "fan_status": (11, 1),
    "self_heating": (12, 1), "ptp_status": (13, 1), "time_sync_status": (14, 3), "system_status": (30, 2),
}


def decode_status_code(code: int) -> dict[str, int]:
    """The named fields of a LiDAR status code (u32)."""
    return {k: (int(code) >> b) & ((1 << w) - 1) for k, (b, w) in STATUS_FIELDS.items()}


def encode_status_code(**fields: int) -> int:
    """A LiDAR status code from named fields (the others 0); raises ValueError for an unknown name
    or a value that does not fit its bits."""
    code = 0
    for k, v in fields.items():
        if k not in STATUS_FIELDS:
            raise ValueError(f"unknown status field {k!r}")
        b, w = STATUS_FIELDS[k]
        if not 0 <= int(v) < (1 << w):
            raise ValueError(f"status field {k}={v} does not fit {w} bits")
        code |= int(v) << b
    return code


def status_problems(code: int) -> list[str]:
    """Short words for the non-normal fields of a status code (empty for a healthy unit), for logs."""
    f = decode_status_code(code)
    words = {"temp_status": "temperature", "volt_status": "voltage", "motor_status": "motor",
             "dirty_warn": "dirty/blocked", "firmware_err": "firmware abnormal", "device_status": "end of life",
             "fan_status": "fan"}
    out = [f"{w} {f[k]}" if STATUS_FIELDS[k][1] > 1 else w for k, w in words.items() if f[k]]
    if f["system_status"]:
        out.append({1: "system warning", 2: "system error"}.get(f["system_status"], f"system {f['system_status']}"))
    return out


def sampling_payload(start: bool) -> bytes:
    return bytes((1 if start else 0,))


def ret_code(payload: bytes) -> int:
    """Return code (first byte) of an ACK payload; 0 = success; 255 if the payload is empty."""
    return payload[0] if payload else 255


def make_cmd(cmd_id: int, seq: int, payload: bytes = b"", cmd_set: int = CMD_SET_GENERAL) -> bytes:
    return encode_control(ControlFrame(CMD_TYPE_CMD, seq, cmd_set, cmd_id, payload))


def make_handshake(seq: int, host_ip: str, data_port: int, cmd_port: int, imu_port: int = 0) -> bytes:
    """The handshake as the vendor SDK frames it: cmd_type 1 (ACK), not 0 (SDK 2.3.0
    ``device_discovery.cpp``, ``packet.packet_type = kCommandTypeAck``); real units take both."""
    return encode_control(ControlFrame(CMD_TYPE_ACK, seq, CMD_SET_GENERAL, CMD_ID_HANDSHAKE,
                                       handshake_payload(host_ip, data_port, cmd_port, imu_port)))


def make_ack(request: ControlFrame, payload: bytes = b"\0") -> bytes:
    return encode_control(ControlFrame(CMD_TYPE_ACK, request.seq, request.cmd_set, request.cmd_id, payload))


def make_broadcast(seq: int, broadcast_code: str, dev_type: int) -> bytes:
    return encode_control(
        ControlFrame(CMD_TYPE_MSG, seq, CMD_SET_GENERAL, CMD_ID_BROADCAST, broadcast_payload(broadcast_code, dev_type))
    )


# --------------------------------------------------------------------------------------------
# data packets

HEADER_DTYPE = np.dtype(
    [
        ("version", "u1"),
        ("slot", "u1"),
        ("id", "u1"),
        ("reserved", "u1"),
        ("err_code", "<u4"),
        ("timestamp_type", "u1"),
        ("data_type", "u1"),
        ("timestamp", "<u8"),
    ]
)
HEADER_LEN = HEADER_DTYPE.itemsize  # 18
assert HEADER_LEN == 18

_CART = [("x", "<i4"), ("y", "<i4"), ("z", "<i4"), ("reflectivity", "u1")]
_SPH = [("depth", "<u4"), ("zenith", "<u2"), ("azimuth", "<u2"), ("reflectivity", "u1")]
POINT_DTYPES: dict[int, np.dtype] = {
    0: np.dtype(_CART),
    1: np.dtype(_SPH),
    2: np.dtype(_CART + [("tag", "u1")]),
    3: np.dtype(_SPH + [("tag", "u1")]),
    4: np.dtype(
        [
            ("x1", "<i4"), ("y1", "<i4"), ("z1", "<i4"), ("reflectivity1", "u1"), ("tag1", "u1"),
            ("x2", "<i4"), ("y2", "<i4"), ("z2", "<i4"), ("reflectivity2", "u1"), ("tag2", "u1"),
        ]
    ),
    5: np.dtype([("zenith", "<u2"), ("azimuth", "<u2")]
                + [(f"{f}{k}", t) for k in (1, 2) for f, t in (("depth", "<u4"), ("reflectivity", "u1"), ("tag", "u1"))]),
    6: np.dtype([("gyro_x", "<f4"), ("gyro_y", "<f4"), ("gyro_z", "<f4"), ("acc_x", "<f4"), ("acc_y", "<f4"), ("acc_z", "<f4")]),
    7: np.dtype([(f"{f}{k}", t) for k in (1, 2, 3)
                 for f, t in (("x", "<i4"), ("y", "<i4"), ("z", "<i4"), ("reflectivity", "u1"), ("tag", "u1"))]),
    8: np.dtype([("zenith", "<u2"), ("azimuth", "<u2")]
                + [(f"{f}{k}", t) for k in (1, 2, 3) for f, t in (("depth", "<u4"), ("reflectivity", "u1"), ("tag", "u1"))]),
}
POINTS_PER_PACKET = {0: 100, 1: 100, 2: 96, 3: 96, 4: 48, 5: 48, 6: 1, 7: 30, 8: 30}
#: Returns per time slot of each point data type (dual 2, triple 3).
RETURNS_PER_SLOT = {0: 1, 1: 1, 2: 1, 3: 1, 4: 2, 5: 2, 7: 3, 8: 3}
IMU_DATA_TYPE = 6
#: IMU packets a :class:`DataDecoder` holds for its reader at most: 10 s at the units' 200 Hz
IMU_QUEUE_PACKETS = 2000
POINT_DATA_TYPES = (0, 1, 2, 3, 4, 5, 7, 8)
CARTESIAN_TYPES = (0, 2, 4, 7)
SPHERICAL_TYPES = (1, 3, 5, 8)
TIMESTAMP_TYPES_NS = (0, 1, 4)
TIMESTAMP_TYPE_UTC = 3


# The Cartesian wire grid (data types 0, 2, 4, 7: x, y, z int32 mm).  The simulator quantises its
# points with these same two functions (sim/sensor.py), so a simulated point and the point a live
# client decodes from the same packet are the same float64 bits, and a recording stores them exactly.
# They live in foveatrack.mm_grid, below both this protocol and the recordings (which pack points on
# the grid); their names stay importable from here.
from foveatrack.mm_grid import INT32_MM_MAX, INT32_MM_MIN, MM_PER_M, m_to_mm, mm_to_m, quantise_to_mm_grid  # noqa: E402,F401


def packet_dtype(data_type: int) -> np.dtype:
    """Structured dtype of one whole data packet of ``data_type`` (header + fixed point array)."""
    return np.dtype([("hdr", HEADER_DTYPE), ("pts", POINT_DTYPES[data_type], (POINTS_PER_PACKET[data_type],))])


def packet_len(data_type: int) -> int:
    return HEADER_LEN + POINTS_PER_PACKET[data_type] * POINT_DTYPES[data_type].itemsize


PACKET_LEN = {dt: packet_len(dt) for dt in POINT_DTYPES}


@dataclass(frozen=True, eq=False)
class PointBatch:
    """Points from one or more data packets.

    xyz : (n, 3) float64 [m], lidar frame (X forward, Y left, Z up)
    reflectivity : (n,) uint8 (0-150 diffuse 0-100 %, > 150 retro-reflective)
    t_ns : (n,) int64 [ns], sensor clock (see the packet timestamp_type)
    tag : (n,) uint8 (0 for data types without a tag)
    """

    xyz: np.ndarray
    reflectivity: np.ndarray
    t_ns: np.ndarray
    tag: np.ndarray

    def __len__(self) -> int:
        return int(self.t_ns.shape[0])

    @staticmethod
    def empty() -> "PointBatch":
        return PointBatch(np.zeros((0, 3)), np.zeros(0, np.uint8), np.zeros(0, np.int64), np.zeros(0, np.uint8))

    @staticmethod
    def concat(batches: Sequence["PointBatch"]) -> "PointBatch":
        batches = [b for b in batches if len(b)]
        if not batches:
            return PointBatch.empty()
        if len(batches) == 1:
            return batches[0]
        return PointBatch(
            np.concatenate([b.xyz for b in batches]),
            np.concatenate([b.reflectivity for b in batches]),
            np.concatenate([b.t_ns for b in batches]),
            np.concatenate([b.tag for b in batches]),
        )


def point_offsets_ns(n: int, point_rate_hz: float) -> np.ndarray:
    """Time of point ``i`` of a packet after its first point [ns], i = 0..n-1."""
    return np.round(np.arange(n) * (1e9 / point_rate_hz)).astype(np.int64)


# The largest sensor timestamp taken [ns]: 2^62 ns is the year 2116 as PTP / UTC time and 146 years
# after power-on; a u64 beyond it (a damaged or hostile packet) would wrap when read as int64 and
# when the point offsets are added to it.
MAX_TIMESTAMP_NS = 1 << 62


def _utc_ns(ts_bytes: np.ndarray) -> np.ndarray:
    """PPS+GPS timestamps: year-2000 u8, month u8, day u8, hour u8, microseconds in the hour u32."""
    out = np.empty(ts_bytes.shape[0], np.int64)
    for k, b in enumerate(ts_bytes):
        us = int.from_bytes(bytes(b[4:8]), "little")
        t = _dt.datetime(2000 + int(b[0]), int(b[1]), int(b[2]), int(b[3]), tzinfo=_dt.timezone.utc)
        out[k] = int(t.timestamp()) * 1_000_000_000 + us * 1000
    return out


def decode_packets_array(arr: np.ndarray, point_rate_hz: float, keep_no_return: bool = False) -> tuple[PointBatch, int]:
    """Decode a structured array of whole packets of one data type (see :func:`packet_dtype`).

    Returns the batch and the number of no-return points removed (0 when ``keep_no_return``).
    Raises :class:`PacketError` (``data_bad_timestamp``) for an invalid UTC timestamp or one at or
    beyond :data:`MAX_TIMESTAMP_NS`.
    """
    hdr = arr["hdr"]
    pts = arr["pts"]
    data_type = int(hdr["data_type"][0])
    n_pk, n_pt = pts.shape
    utc = hdr["timestamp_type"] == TIMESTAMP_TYPE_UTC
    raw_ts = hdr["timestamp"]
    if (raw_ts[~utc] >= MAX_TIMESTAMP_NS).any():
        bad = int(raw_ts[~utc][raw_ts[~utc] >= MAX_TIMESTAMP_NS][0])
        raise PacketError("data_bad_timestamp", f"timestamp 0x{bad:016x} ns is beyond any sensor clock "
                                                f"(>= 2^62 ns)")
    ts = raw_ts.astype(np.int64)
    if utc.any():
        raw = arr.view(np.uint8).reshape(n_pk, -1)[:, 10:18]
        try:
            ts[utc] = _utc_ns(raw[utc])
        except (ValueError, OverflowError) as exc:
            raise PacketError("data_bad_timestamp", str(exc)) from None
    t = (ts[:, None] + point_offsets_ns(n_pt, point_rate_hz)[None, :]).reshape(-1)
    pdt = POINT_DTYPES[data_type]
    per = RETURNS_PER_SLOT.get(data_type, 0)
    if per > 1:
        t = np.repeat(t, per)   # every return of a slot has the slot's time
    if data_type in CARTESIAN_TYPES:
        # x, y, z (and x2.. z3) as one strided int32 view of the packed bytes: a single copy
        step = pdt.itemsize // per
        mm = np.ndarray(
            (n_pk, n_pt, per, 3), "<i4", buffer=arr, offset=HEADER_LEN, strides=(arr.dtype.itemsize, pdt.itemsize, step, 4)
        ).reshape(-1, 3)
        raw = np.ndarray((n_pk, n_pt, per, step), "u1", buffer=arr, offset=HEADER_LEN,
                         strides=(arr.dtype.itemsize, pdt.itemsize, step, 1))
        refl = raw[..., 12].reshape(-1)
        tag = raw[..., 13].reshape(-1) if data_type != 0 else np.zeros(n_pk * n_pt, np.uint8)
        ok = None if keep_no_return else (mm[:, 0] | mm[:, 1] | mm[:, 2]) != 0
        if ok is not None:
            keep = np.flatnonzero(ok)  # take() with indices is ~5x faster than a 2-D boolean mask
            mm, refl, tag, t = mm.take(keep, axis=0), refl.take(keep), tag.take(keep), t.take(keep)
        xyz = mm_to_m(mm)
    elif data_type in SPHERICAL_TYPES:
        if per == 1:
            depth = pts["depth"].reshape(-1)
            refl = pts["reflectivity"].reshape(-1)
            tag = pts["tag"].reshape(-1) if data_type == 3 else np.zeros(n_pk * n_pt, np.uint8)
            zen, azi = pts["zenith"].reshape(-1), pts["azimuth"].reshape(-1)
        else:   # the returns of a slot share its direction
            ks = range(1, per + 1)
            depth = np.stack([pts[f"depth{k}"] for k in ks], axis=-1).reshape(-1)
            refl = np.stack([pts[f"reflectivity{k}"] for k in ks], axis=-1).reshape(-1)
            tag = np.stack([pts[f"tag{k}"] for k in ks], axis=-1).reshape(-1)
            zen, azi = np.repeat(pts["zenith"].reshape(-1), per), np.repeat(pts["azimuth"].reshape(-1), per)
        ok = None if keep_no_return else depth != 0
        if ok is not None:
            depth, refl, tag, t, zen, azi = depth[ok], refl[ok], tag[ok], t[ok], zen[ok], azi[ok]
        r = depth * 1e-3
        th = np.deg2rad(zen * 0.01)
        ph = np.deg2rad(azi * 0.01)
        st = np.sin(th)
        xyz = np.stack([r * st * np.cos(ph), r * st * np.sin(ph), r * np.cos(th)], axis=-1)
    else:
        raise ValueError(f"data type {data_type} carries no points")
    n_removed = 0 if ok is None else int(ok.size - np.count_nonzero(ok))
    return PointBatch(xyz, np.ascontiguousarray(refl), np.ascontiguousarray(t), np.ascontiguousarray(tag)), n_removed


def classify_data(buf: bytes) -> tuple[int | None, str | None]:
    """Cheap per-datagram validation: ``(data_type, None)`` if decodable, else ``(None, reason)``.

    IMU packets validate to data type 6 (the caller counts and skips them).
    """
    n = len(buf)
    if n < HEADER_LEN:
        return None, "data_truncated_header"
    if buf[0] != DATA_VERSION:
        return None, "data_bad_version"
    dt = buf[9]
    if dt not in PACKET_LEN:
        return None, "data_unknown_type"
    if buf[8] not in TIMESTAMP_TYPES_NS and buf[8] != TIMESTAMP_TYPE_UTC:
        return None, "data_unknown_timestamp_type"
    exp = PACKET_LEN[dt]
    if n < exp:
        return None, "data_truncated"
    if n > exp:
        return None, "data_oversize"
    return dt, None


@dataclass
class DataDecoder:
    """Safe decoder of Livox data datagrams; nothing fed to :meth:`decode` makes it raise.

    point_rate_hz : float > 0 [points/s], the sensor's single-return point rate (gives per-point time)
    keep_no_return : keep (0, 0, 0) points (default: drop and count them)
    keep_imu : hold IMU packets for :meth:`take_imu` (a reader that takes none sets it False: a
        Horizon, Avia or Tele-15 streams 200 packets/s, ~1 MB/min that nothing would free)
    imu_queue_packets : int >= 1, the most IMU packets held; beyond, the oldest go (counted)

    ``counters``: packets (accepted point packets), points (points returned), imu_packets,
    imu_packets_unused (not held: ``keep_imu`` False), imu_packets_dropped (the queue was full),
    wire_points = returns + no_return_points (kept or not), and ``dropped`` {reason: count}.
    """

    point_rate_hz: float = 240_000.0
    keep_no_return: bool = False
    keep_imu: bool = True
    imu_queue_packets: int = IMU_QUEUE_PACKETS
    counters: Counter = field(default_factory=Counter)
    dropped: Counter = field(default_factory=Counter)

    def __post_init__(self) -> None:
        if not self.point_rate_hz > 0:
            raise UserError(f"point_rate_hz must be > 0, got {self.point_rate_hz!r}")
        if not self.imu_queue_packets >= 1:
            raise UserError(f"imu_queue_packets must be >= 1, got {self.imu_queue_packets!r}")
        self.last_err_code: int | None = None  # status code (err_code) of the newest accepted packet
        self._imu: deque = deque(maxlen=int(self.imu_queue_packets))

    def take_imu(self) -> "ImuBatch":
        """The IMU samples (data type 6) decoded since the last call, in arrival order (at most the
        newest ``imu_queue_packets``; nothing while ``keep_imu`` is False)."""
        bufs = list(self._imu)
        self._imu.clear()
        return decode_imu_packets(bufs)

    def decode(self, datagrams: Iterable[bytes]) -> list[PointBatch]:
        """Decode datagrams; returns one batch per run of consecutive packets of one data type."""
        runs: list[tuple[int, list[bytes]]] = []
        for buf in datagrams:
            dt, reason = classify_data(buf)
            if reason is not None:
                self.dropped[reason] += 1
                continue
            self.last_err_code = int.from_bytes(buf[4:8], "little")
            if dt == IMU_DATA_TYPE:
                self.counters["imu_packets"] += 1
                if not self.keep_imu:
                    self.counters["imu_packets_unused"] += 1
                    continue
                if len(self._imu) == self._imu.maxlen:
                    self.counters["imu_packets_dropped"] += 1     # the oldest: nobody took them
                self._imu.append(bytes(buf))
                continue
            if runs and runs[-1][0] == dt:
                runs[-1][1].append(buf)
            else:
                runs.append((dt, [buf]))
        out = []
        for dt, bufs in runs:
            arr = np.frombuffer(b"".join(bufs), dtype=packet_dtype(dt))
            try:
                batch, n_removed = decode_packets_array(arr, self.point_rate_hz, self.keep_no_return)
                n_good = arr.shape[0]
            except PacketError:
                # rare (an invalid UTC date): one packet at a time, keeping the good ones
                batch, n_removed, n_good = self._decode_one_by_one(arr)
            self.counters["packets"] += n_good
            # counts that add up whether no-returns are kept or not: wire_points (every slot's return on
            # the wire) = returns + no_return_points (a kept no-return was once counted as a point and
            # no_return_points said 0 while 80 % of the wire was no-return)
            n_nr = n_removed
            if self.keep_no_return and len(batch):
                n_nr = len(batch) - int(np.count_nonzero(np.any(batch.xyz != 0.0, axis=1)))
            self.counters["wire_points"] += len(batch) + n_removed
            self.counters["no_return_points"] += n_nr
            self.counters["returns"] += len(batch) + n_removed - n_nr
            self.counters["points"] += len(batch)
            if len(batch):
                out.append(batch)
        return out

    def _decode_one_by_one(self, arr: np.ndarray) -> tuple[PointBatch, int, int]:
        good, removed = [], 0
        for k in range(arr.shape[0]):
            try:
                b, r = decode_packets_array(arr[k : k + 1], self.point_rate_hz, self.keep_no_return)
            except PacketError as exc:
                self.dropped[exc.reason] += 1
                continue
            good.append(b)
            removed += r
        return PointBatch.concat(good), removed, len(good)

    def decode_one(self, buf: bytes) -> PointBatch:
        """Decode one datagram (counts as :meth:`decode`); empty batch if it was dropped."""
        return PointBatch.concat(self.decode([buf]))


def decode_packet(buf: bytes, point_rate_hz: float = 240_000.0, keep_no_return: bool = False) -> PointBatch:
    """Strict decode of one point packet; raises :class:`PacketError` with the reason."""
    dt, reason = classify_data(buf)
    if reason is not None:
        raise PacketError(reason, f"{len(buf)} bytes")
    if dt == IMU_DATA_TYPE:
        raise PacketError("data_unknown_type", "IMU packet carries no points")
    return decode_packets_array(np.frombuffer(bytes(buf), dtype=packet_dtype(dt)), point_rate_hz, keep_no_return)[0]


# -- encoder (the virtual sensor and the tests need it)


def encode_data_packets(
    xyz_m: np.ndarray,
    reflectivity: np.ndarray,
    t0_ns: int,
    point_rate_hz: float,
    data_type: int = 2,
    tag: np.ndarray | None = None,
    timestamp_type: int = 0,
    err_code: int = 0,
    slot: int = 1,
    lidar_id: int = 1,
) -> list[bytes]:
    """Pack points, one per time slot, into whole data packets.

    xyz_m : (n, 3) [m] lidar frame; rows of zeros are "no return" slots.  Point ``i`` is at time
    ``t0_ns + i / point_rate_hz``; packet ``k`` is stamped with the time of its first slot.  The last
    packet is padded with no-return slots.  For the multi-return types (4, 5 dual; 7, 8 triple)
    consecutive rows are the returns of one slot (the spherical ones store one direction per slot:
    that of its first return with a range, the others keep only their range).  Values are rounded to the wire resolution (1 mm, 0.01 deg).
    """
    if data_type not in POINT_DATA_TYPES:
        raise ValueError(f"cannot encode data type {data_type}")
    xyz_m = np.asarray(xyz_m, dtype=np.float64).reshape(-1, 3)
    refl = np.asarray(reflectivity, dtype=np.uint8).reshape(-1)
    tag = np.zeros(len(refl), np.uint8) if tag is None else np.asarray(tag, np.uint8).reshape(-1)
    per_slot = RETURNS_PER_SLOT[data_type]
    n_slots = -(-len(refl) // per_slot)
    n_per = POINTS_PER_PACKET[data_type]
    n_pk = -(-n_slots // n_per)
    if n_pk == 0:
        return []
    total = n_pk * n_per * per_slot
    pad = total - len(refl)
    if pad:
        xyz_m = np.concatenate([xyz_m, np.zeros((pad, 3))])
        refl = np.concatenate([refl, np.zeros(pad, np.uint8)])
        tag = np.concatenate([tag, np.zeros(pad, np.uint8)])
    arr = np.zeros(n_pk, dtype=packet_dtype(data_type))
    h = arr["hdr"]
    h["version"] = DATA_VERSION
    h["slot"] = slot
    h["id"] = lidar_id
    h["err_code"] = err_code
    h["timestamp_type"] = timestamp_type
    h["data_type"] = data_type
    h["timestamp"] = t0_ns + np.round(np.arange(n_pk) * n_per * (1e9 / point_rate_hz)).astype(np.int64)
    p = arr["pts"]
    if data_type in CARTESIAN_TYPES:
        mm = m_to_mm(xyz_m).reshape(n_pk, n_per, per_slot, 3)
        rr = refl.reshape(n_pk, n_per, per_slot)
        tt = tag.reshape(n_pk, n_per, per_slot)
        for k in range(per_slot):
            sfx = "" if per_slot == 1 else str(k + 1)
            p[f"x{sfx}"], p[f"y{sfx}"], p[f"z{sfx}"] = mm[:, :, k, 0], mm[:, :, k, 1], mm[:, :, k, 2]
            p[f"reflectivity{sfx}"] = rr[:, :, k]
            if data_type != 0:
                p[f"tag{sfx}"] = tt[:, :, k]
    else:
        x, y, z = xyz_m[:, 0], xyz_m[:, 1], xyz_m[:, 2]
        r = np.sqrt(x * x + y * y + z * z)
        th = np.degrees(np.arctan2(np.hypot(x, y), z))
        ph = np.degrees(np.arctan2(y, x)) % 360.0
        depth = np.round(r * 1000.0).astype(np.int64).clip(0, 2**32 - 1).reshape(n_pk, n_per, per_slot)
        zen = np.round(th * 100.0).astype(np.int64).clip(0, 18000).reshape(n_pk, n_per, per_slot)
        azi = (np.round(ph * 100.0).astype(np.int64) % 36000).reshape(n_pk, n_per, per_slot)
        rr = refl.reshape(n_pk, n_per, per_slot)
        tt = tag.reshape(n_pk, n_per, per_slot)
        if per_slot == 1:
            p["depth"], p["zenith"], p["azimuth"] = depth[..., 0], zen[..., 0], azi[..., 0]
            p["reflectivity"] = rr[..., 0]
            if data_type == 3:
                p["tag"] = tt[..., 0]
        else:
            # one direction per slot: that of its first return with a range (zenith 0 if none has one)
            first = np.argmax(depth > 0, axis=-1)[..., None]
            p["zenith"] = np.take_along_axis(zen, first, -1)[..., 0]
            p["azimuth"] = np.take_along_axis(azi, first, -1)[..., 0]
            for k in range(per_slot):
                p[f"depth{k + 1}"], p[f"reflectivity{k + 1}"], p[f"tag{k + 1}"] = depth[..., k], rr[..., k], tt[..., k]
    raw = arr.tobytes()
    L = arr.dtype.itemsize
    return [raw[k * L : (k + 1) * L] for k in range(n_pk)]


# --------------------------------------------------------------------------------------------
# IMU packets (data type 6: one sample each, 200 Hz on Horizon, Tele-15 and Avia)


@dataclass(frozen=True, eq=False)
class ImuBatch:
    """IMU samples.  gyro_rad_s : (n, 3) float [rad/s]; acc_g : (n, 3) float [g] (specific force,
    a level sensor at rest reads about (0, 0, 1)); t_ns : (n,) int64 [ns], packet timestamps.
    Axes are the lidar's (X forward, Y left, Z up; SDK ``LivoxImuPoint``)."""

    gyro_rad_s: np.ndarray
    acc_g: np.ndarray
    t_ns: np.ndarray

    def __len__(self) -> int:
        return int(self.t_ns.shape[0])

    @staticmethod
    def empty() -> "ImuBatch":
        return ImuBatch(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int64))

    @staticmethod
    def concat(batches: Sequence["ImuBatch"]) -> "ImuBatch":
        batches = [b for b in batches if len(b)]
        if not batches:
            return ImuBatch.empty()
        return ImuBatch(np.concatenate([b.gyro_rad_s for b in batches]), np.concatenate([b.acc_g for b in batches]),
                        np.concatenate([b.t_ns for b in batches]))


IMU_PACKET_DTYPE = np.dtype([("hdr", HEADER_DTYPE), ("imu", POINT_DTYPES[IMU_DATA_TYPE])])


def encode_imu_packets(t_ns: np.ndarray, gyro_rad_s: np.ndarray, acc_g: np.ndarray, timestamp_type: int = 0,
                       err_code: int = 0, slot: int = 1, lidar_id: int = 1) -> list[bytes]:
    """One data-type-6 packet per sample (t_ns (n,) [ns]; gyro (n, 3) [rad/s]; acc (n, 3) [g])."""
    t = np.asarray(t_ns, np.int64).reshape(-1)
    g = np.asarray(gyro_rad_s, np.float64).reshape(-1, 3)
    a = np.asarray(acc_g, np.float64).reshape(-1, 3)
    arr = np.zeros(t.size, IMU_PACKET_DTYPE)
    h = arr["hdr"]
    h["version"], h["slot"], h["id"], h["err_code"] = DATA_VERSION, slot, lidar_id, err_code
    h["timestamp_type"], h["data_type"], h["timestamp"] = timestamp_type, IMU_DATA_TYPE, t
    for k, ax in enumerate("xyz"):
        arr["imu"][f"gyro_{ax}"] = g[:, k]
        arr["imu"][f"acc_{ax}"] = a[:, k]
    raw = arr.tobytes()
    L = IMU_PACKET_DTYPE.itemsize
    return [raw[k * L:(k + 1) * L] for k in range(t.size)]


def decode_imu_packets(bufs: Sequence[bytes]) -> ImuBatch:
    """Decode whole IMU packets (each already validated by :func:`classify_data` as type 6).
    A UTC-stamped packet with an invalid date is dropped."""
    if not bufs:
        return ImuBatch.empty()
    arr = np.frombuffer(b"".join(bufs), IMU_PACKET_DTYPE)
    ts = arr["hdr"]["timestamp"].astype(np.int64)
    keep = np.ones(arr.shape[0], bool)
    utc = arr["hdr"]["timestamp_type"] == TIMESTAMP_TYPE_UTC
    for k in np.flatnonzero(utc):
        raw = np.frombuffer(bufs[k][10:18], np.uint8)[None, :]
        try:
            ts[k] = _utc_ns(raw)[0]
        except (ValueError, OverflowError):
            keep[k] = False
    imu = arr["imu"][keep]
    gyro = np.stack([imu["gyro_x"], imu["gyro_y"], imu["gyro_z"]], axis=1).astype(np.float64)
    acc = np.stack([imu["acc_x"], imu["acc_y"], imu["acc_z"]], axis=1).astype(np.float64)
    return ImuBatch(gyro, acc, ts[keep])

