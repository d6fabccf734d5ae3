"""A foveatrack recording (``.mcap``) as a Livox Viewer ``.lvx`` v1.1 file.

Every recorded point is put back into its firing slot: slot ``k`` of a device is at
``t_origin + k / point_rate_hz`` (the recorded per-point times lie on that grid: the simulator fires
point k at k / rate, a real unit sends one slot per point interval), the slots are packed into SDK v1
data packets of the chosen data type (empty slots as "no return", as a real unit sends them), and
the packets go into LVX frames of ``frame_duration_ms`` by packet time.  Reading the file back gives
the recorded points to the wire resolution (1 mm; 0.01 deg and 1 mm for the spherical types) at the
recorded times (to 1 ns: the packet timestamp and the in-packet offset are rounded separately).
The file appears under its name only when it is whole (:mod:`foveatrack.atomic_file`).

The multi-return types (4, 5 dual; 7, 8 triple) carry each recorded point as the first return of its
slot and leave the other returns empty: recordings hold one return per slot.  Two recorded points in
one slot (never from the simulator's lidar; possible in a hand-made recording) cannot both be
written: the later ones are counted in ``slot_collisions`` and left out.
"""

from __future__ import annotations

import os
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from foveatrack.atomic_file import written_whole
from foveatrack.errors import UserError
from foveatrack.livox import protocol as P
from foveatrack.livox.lvx import LvxDevice, write_lvx

#: Data type a real unit of each device type sends by default (Mid-40: Cartesian; the others:
#: extended Cartesian), Livox SDK v1 / livox_ros_driver.
DEFAULT_DATA_TYPE = {1: 0, 2: 2, 3: 2, 6: 2, 7: 2}
#: Presets with several heads, each its own LVX device: yaw of each head [deg] (Mid-100: three Mid-40s).
MULTI_HEAD_YAW_DEG = {"mid100": (30.0, 0.0, -30.0)}
#: Device type of each preset name (the simulator's own prototype is a Mid-40).
PRESET_DEVICE_TYPE = {**P.DEVICE_TYPES, "prototype": 1, "mid100": 1}


#: a gap in the recorded point times up to this long [s] is filled with empty slots and frames, as a
#: unit sends them; a longer one (a sensor clock that jumped, from power-on time to PTP time) is not:
#: the slots and frames after it follow on, so no array or frame count is sized by a time span
MAX_FILLED_GAP_S = 1.0


@dataclass(frozen=True)
class LvxExport:
    """What :func:`export_lvx` wrote."""

    path: Path
    device_type: int
    data_type: int
    devices: int
    points: int
    packets: int
    frames: int
    slot_collisions: int
    problem: str | None = None        # the reader's warning: what a damaged recording lost (None: nothing)
    time_gaps: int = 0                # gaps in the points' times over MAX_FILLED_GAP_S, not filled with frames
    guessed: str | None = None        # the device was guessed (the recording names no lidar): how, in words


def _preset_of(meta: dict) -> str | None:
    text = meta.get("scene_text")
    if not text:
        lidar = meta.get("lidar")
        return lidar.get("preset") if isinstance(lidar, dict) else None
    try:
        lidar = tomllib.loads(text).get("lidar", {})
    except tomllib.TOMLDecodeError:
        return None
    return lidar.get("preset") if isinstance(lidar, dict) else None


def export_lvx(recording: str | os.PathLike, out_path: str | os.PathLike, data_type: int | None = None,
               device: str | None = None, frame_duration_ms: int = 50, max_frames: int | None = None) -> LvxExport:
    """Write the points of ``recording`` to ``out_path`` as LVX v1.1.

    data_type : SDK v1 point data type 0-5, 7, 8 (default: the device's own, see DEFAULT_DATA_TYPE)
    device : preset / device name (mid40, horizon, tele15, mid70, avia, mid100); default from the
        recording's scene, else by point rate (100 k/s Mid-40, otherwise Horizon)
    frame_duration_ms : LVX frame length [ms], 1..1000 (Livox Viewer writes 50)
    max_frames : the cap on frames read (default the reader's for the file's size; ``problem`` says
        when it stopped the reading)
    """
    from foveatrack.recording.segments import open_run

    if data_type is not None and data_type not in P.POINT_DATA_TYPES:
        raise UserError(f"LVX data type {data_type}: must be one of {list(P.POINT_DATA_TYPES)} "
                        "(6 is the Livox IMU packet: --lvx writes points; a recording's IMU samples go out with --imu)")
    if not 1 <= frame_duration_ms <= 1000:
        raise UserError(f"frame duration {frame_duration_ms} ms: must be 1..1000")
    reader = open_run(recording, max_frames, segment_alone=True)
    meta = reader.meta or {}
    name = device or _preset_of(meta)
    rate = meta.get("point_rate_hz")
    guessed = None
    if name is None:
        name = "mid40" if rate in (None, 100_000) else "horizon"
        # a recording of someone else's lidar (track --record) names none: said, not written as a fact
        guessed = (f"the recording names no lidar, so the file calls it a {name} (device type "
                   f"{PRESET_DEVICE_TYPE[name]}), guessed from {'no recorded point rate' if rate is None else f'its point rate {rate:g}/s'}; "
                   "--device names the real one (mid40, horizon, tele15, mid70, avia, mid100)")
    if name not in PRESET_DEVICE_TYPE:
        raise UserError(f"device {name!r}: LVX device types are known for {sorted(PRESET_DEVICE_TYPE)}")
    dev_type = PRESET_DEVICE_TYPE[name]
    yaws = MULTI_HEAD_YAW_DEG.get(name, (0.0,))
    n_heads = len(yaws)
    if rate is None:
        rate = P.DEVICE_POINT_RATE_HZ[dev_type] * n_heads
    rate = float(rate)
    if not rate > 0:
        raise UserError(f"{recording}: recorded point rate {rate!r} is not a rate")
    dt = DEFAULT_DATA_TYPE.get(dev_type, 2) if data_type is None else data_type

    frames = list(reader.points())
    problem = reader.warning()
    if frames:
        t = np.concatenate([f.t_ns_points for f in frames])
        xyz = np.concatenate([f.xyz for f in frames])
        refl = np.concatenate([f.reflectivity for f in frames]).astype(np.uint8)
    else:
        t, xyz, refl = np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0, np.uint8)
    devices = [LvxDevice(f"VLIVOX{name.upper()[:6]}{h:03d}"[:15], "", h, dev_type, n_heads > 1, 0.0, 0.0, yaw, 0.0, 0.0, 0.0)
               for h, yaw in enumerate(yaws)]
    if not len(t):
        with written_whole(out_path) as tmp:
            write_lvx(tmp, [], devices, frame_duration_ms)
        return LvxExport(Path(out_path), dev_type, dt, n_heads, 0, 0, 0, 0, problem=problem, guessed=guessed)
    t_origin = int(t.min())
    slot = np.round((t - t_origin) * (rate / 1e9)).astype(np.int64)
    order = np.lexsort((np.arange(len(slot)), slot))
    slot, xyz, refl = slot[order], xyz[order], refl[order]
    first = np.ones(len(slot), bool)
    first[1:] = slot[1:] != slot[:-1]
    collisions = int((~first).sum())
    slot, xyz, refl = slot[first], xyz[first], refl[first]

    per = P.RETURNS_PER_SLOT[dt]
    head_rate = rate / n_heads
    frame_ns = frame_duration_ms * 1_000_000
    packets: dict[int, list[tuple[int, bytes]]] = {}
    n_packets = 0
    max_gap_slots = int(MAX_FILLED_GAP_S * head_rate)
    for h in range(n_heads):
        mine = slot % n_heads == h                       # head h fires slots h, h + H, ... (point k: head k mod H)
        hs_all = slot[mine] // n_heads
        if not hs_all.size:
            continue
        xyz_h, refl_h = xyz[mine], refl[mine]
        # runs of slots without a gap over MAX_FILLED_GAP_S: the grid is never sized by a time span
        # (a sensor clock jump once asked for 3.83 PiB); empty slots are filled inside a run only
        cuts = np.flatnonzero(np.diff(hs_all) > max_gap_slots) + 1
        for a, b in zip(np.concatenate(([0], cuts)), np.concatenate((cuts, [hs_all.size]))):
            s0 = int(hs_all[a])
            hs = hs_all[a:b] - s0
            n_slots = int(hs[-1]) + 1
            grid = np.zeros((n_slots, per, 3))
            grid_refl = np.zeros((n_slots, per), np.uint8)
            grid[hs, 0] = xyz_h[a:b]
            grid_refl[hs, 0] = refl_h[a:b]
            t0_h = t_origin + int(round(h * 1e9 / rate)) + int(round(s0 * 1e9 / head_rate))
            pks = P.encode_data_packets(grid.reshape(-1, 3), grid_refl.reshape(-1), t0_h, head_rate, data_type=dt,
                                        lidar_id=1)
            n_per = P.POINTS_PER_PACKET[dt]
            for k, pk in enumerate(pks):
                t_pk = t0_h + int(round(k * n_per * 1e9 / head_rate))
                packets.setdefault((t_pk - t_origin) // frame_ns, []).append((t_pk, h, pk))
            n_packets += len(pks)
    lvx_frames = []
    gaps = 0
    prev = None
    for k in sorted(packets):
        if prev is not None and k - prev > 1:
            if (k - prev - 1) * frame_ns <= MAX_FILLED_GAP_S * 1e9:
                lvx_frames.extend([] for _ in range(k - prev - 1))   # frames keep coming over the sky
            else:
                gaps += 1                                           # not a time span to fill with frames
        prev = k
        fr = sorted(packets[k], key=lambda x: (x[0], x[1]))
        lvx_frames.append([(h, pk) for _, h, pk in fr])
    with written_whole(out_path) as tmp:          # under its name only when whole (an export cut by Ctrl-C)
        write_lvx(tmp, lvx_frames, devices, frame_duration_ms)
    return LvxExport(Path(out_path), dev_type, dt, n_heads, int(len(slot)), n_packets, len(lvx_frames), collisions,
                     problem=problem, time_gaps=gaps, guessed=guessed)
