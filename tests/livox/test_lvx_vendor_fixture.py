"""Our LVX writer and reader against bytes the vendor's own writer produced (Livox SDK 2.3.0
``LvxFileHandle``, run once in a local harness outside the project; docs/livox-files.md):
packets of every data type 0-8, two devices, three frames."""

import struct
from pathlib import Path

import numpy as np

from foveatrack.livox import protocol as P
from foveatrack.livox.lvx import DEVICE_INFO, LvxDevice, LvxReader, write_lvx

FIX = Path(__file__).parent / "fixtures"


def _input():
    buf = (FIX / "vendor_lvx_input.bin").read_bytes()
    n_dev, pos = buf[0], 1
    devices = []
    for _ in range(n_dev):
        lc, hc, idx, dtype, ext, *pose = DEVICE_INFO.unpack_from(buf, pos)
        devices.append(LvxDevice(lc.rstrip(b"\0").decode(), hc.rstrip(b"\0").decode(), idx, dtype, bool(ext), *pose))
        pos += DEVICE_INFO.size
    frames = []
    while pos < len(buf):
        (n,) = struct.unpack_from("<I", buf, pos)
        pos += 4
        frame = []
        for _ in range(n):
            dev, length = struct.unpack_from("<BH", buf, pos)
            frame.append((dev, buf[pos + 3 : pos + 3 + length]))
            pos += 3 + length
        frames.append(frame)
    return devices, frames


def test_our_writer_is_byte_identical_to_the_vendors(tmp_path):
    devices, frames = _input()
    assert sorted({pk[9] for fr in frames for _, pk in fr}) == list(range(9))
    write_lvx(tmp_path / "ours.lvx", frames, devices)
    assert (tmp_path / "ours.lvx").read_bytes() == (FIX / "vendor_lvx_writer.lvx").read_bytes()


def test_our_reader_gives_what_the_packet_decoder_gives_for_the_vendors_file():
    devices, frames = _input()
    rates = {d.device_index: P.DEVICE_POINT_RATE_HZ[d.device_type] for d in devices}
    with LvxReader(FIX / "vendor_lvx_writer.lvx") as r:
        got = list(r.frames())
        assert r.counters["imu_packets"] == 3
    assert [f.frame_index for f in got] == [0, 1, 2]
    for f, fr in zip(got, frames):
        want = []
        for dev in sorted({d for d, _ in fr}, key=[d for d, _ in fr].index):
            want += P.DataDecoder(rates[dev]).decode([pk for d, pk in fr if d == dev])
        want = P.PointBatch.concat(want)
        np.testing.assert_array_equal(f.points.xyz, want.xyz)
        np.testing.assert_array_equal(f.points.t_ns, want.t_ns)
        np.testing.assert_array_equal(f.points.tag, want.tag)
        imu = [pk for _, pk in fr if pk[9] == 6]
        np.testing.assert_array_equal(f.imu.gyro_rad_s[0], np.frombuffer(imu[0][18:30], "<f4"))
