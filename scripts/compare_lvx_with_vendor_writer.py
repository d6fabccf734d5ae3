"""Write the same packets with the Livox SDK 2.3.0's own LVX writer and with ours; compare the bytes.

Needs the vendor SDK's source (Livox-SDK/Livox-SDK, tag v2.3.0; kept outside the project) and g++.
The harness (``scripts/vendor/lvx_writer_harness.cpp``) links the SDK's ``sample/lidar_lvx_file``
``LvxFileHandle`` (``lvx_file.cpp``: public/private headers, device infos, ``BasePointsHandle`` and
``SaveFrameToLvxFile``) and feeds it packets of every data type 0-8 that our encoder makes, in two
devices and three frames; the script writes the same frames with ``foveatrack.livox.lvx.write_lvx``
and ``foveatrack export``'s packet layout, then compares the files byte for byte and reads the
vendor's file back with our reader.

Usage: python scripts/compare_lvx_with_vendor_writer.py SDK_SOURCE_DIR [--fixture DIR]
(SDK_SOURCE_DIR holds sample/lidar_lvx_file and sdk_core/include, e.g. from a clone of
Livox-SDK/Livox-SDK: ``git archive v2.3.0 sample/lidar_lvx_file sdk_core/include | tar -x -C DIR``.)
``--fixture DIR`` also keeps the harness input (``vendor_lvx_input.bin``) and the vendor's file
(``vendor_lvx_writer.lvx``) there: ``tests/livox/test_lvx_vendor_fixture.py`` checks our writer
against them where the SDK is not present (CI).
"""

from __future__ import annotations

import struct
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from foveatrack.livox import protocol as P
from foveatrack.livox.lvx import DEVICE_INFO, LvxDevice, LvxReader, write_lvx

HERE = Path(__file__).resolve().parent


def packets(rng) -> list[list[tuple[int, bytes]]]:
    frames = []
    t0 = 7 * 10**9
    for f in range(3):
        frame = []
        for dt in (*P.POINT_DATA_TYPES, P.IMU_DATA_TYPE):
            if dt == P.IMU_DATA_TYPE:
                hdr = struct.pack("<BBBBIBBQ", 5, 1, 1, 0, 0, 0, 6, t0)
                frame.append((1, hdr + struct.pack("<6f", *rng.normal(size=6))))
                continue
            n = P.POINTS_PER_PACKET[dt] * P.RETURNS_PER_SLOT[dt]
            xyz = rng.uniform(-80, 80, (n, 3))
            pk = P.encode_data_packets(xyz, rng.integers(0, 256, n), t0, 240_000.0, data_type=dt,
                                       tag=rng.integers(0, 256, n), err_code=int(rng.integers(0, 2**31)))
            frame.append((dt % 2, pk[0]))
        t0 += 50_000_000
        frames.append(frame)
    return frames


def main() -> int:
    args = sys.argv[1:]
    fixture = None
    if "--fixture" in args:
        i = args.index("--fixture")
        fixture = Path(args[i + 1])
        del args[i : i + 2]
    if len(args) != 1:
        print(__doc__)
        return 2
    sdk = Path(args[0]).resolve()
    src = sdk / "sample" / "lidar_lvx_file"
    if not (src / "lvx_file.cpp").is_file():
        print(f"{src}/lvx_file.cpp not found: give the SDK 2.3.0 source directory")
        return 2
    rng = np.random.default_rng(15)
    frames = packets(rng)
    devices = [LvxDevice("3WEDH7600101621", "", 0, 3, False, 0, 0, 0, 0, 0, 0),
               LvxDevice("1PQDH5B00100041", "", 1, 1, True, 1.5, -2.0, 30.0, 0.1, -0.2, 0.3)]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        exe = tmp / "harness"
        subprocess.run(["g++", "-std=c++14", "-O1", "-include", "memory", "-include", "thread", "-w",
                        f"-I{src}", f"-I{sdk / 'sdk_core' / 'include'}", str(HERE / "vendor" / "lvx_writer_harness.cpp"),
                        str(src / "lvx_file.cpp"), "-o", str(exe)], check=True)
        inp = bytearray([len(devices)])
        for d in devices:
            inp += DEVICE_INFO.pack(d.lidar_code.encode().ljust(16, b"\0"), d.hub_code.encode().ljust(16, b"\0"),
                                    d.device_index, d.device_type, int(d.extrinsic_enable),
                                    d.roll_deg, d.pitch_deg, d.yaw_deg, d.x_m, d.y_m, d.z_m)
        for fr in frames:
            inp += struct.pack("<I", len(fr))
            for dev, pk in fr:
                inp += struct.pack("<BH", dev, len(pk)) + pk
        (tmp / "in.bin").write_bytes(bytes(inp))
        subprocess.run([str(exe), str(tmp / "in.bin")], cwd=tmp, check=True)
        (vendor,) = tmp.glob("*.lvx")
        if fixture is not None:
            fixture.mkdir(parents=True, exist_ok=True)
            (fixture / "vendor_lvx_input.bin").write_bytes(bytes(inp))
            (fixture / "vendor_lvx_writer.lvx").write_bytes(vendor.read_bytes())
        ours = tmp / "ours.lvx"
        write_lvx(ours, frames, devices)
        a, b = vendor.read_bytes(), ours.read_bytes()
        types = sorted({pk[9] for fr in frames for _, pk in fr})
        print(f"vendor LvxFileHandle: {len(a)} bytes; foveatrack write_lvx: {len(b)} bytes; data types {types}, "
              f"{sum(len(f) for f in frames)} packages in {len(frames)} frames")
        same = a == b
        if not same:
            k = next((i for i in range(min(len(a), len(b))) if a[i] != b[i]), min(len(a), len(b)))
            print(f"DIFFER from byte {k}: vendor {a[k:k + 16].hex()} ours {b[k:k + 16].hex()}")
        with LvxReader(vendor) as r:
            n = sum(len(f.points) for f in r.frames())
            print(f"our reader on the vendor's file: {n} points, {r.counters['imu_packets']} IMU samples, "
                  f"devices {[(d.device_index, d.device_type) for d in r.devices]}")
        print("byte-identical" if same else "NOT byte-identical")
        return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
