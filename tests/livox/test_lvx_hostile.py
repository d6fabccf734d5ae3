"""Hostile .lvx files (issue 32): a wild package timestamp is a one-line error naming the package and
the field, or a warning with the counts of what was dropped; never a traceback, never silent loss."""

import numpy as np
import pytest

from foveatrack.errors import UserError
from foveatrack.livox import protocol as P
from foveatrack.livox.lvx import LvxDevice, read_lvx, write_lvx

AVIA = LvxDevice("3JEDK1B00100961", "", 2, 7, False, 0, 0, 0, 0, 0, 0)


def _file(tmp_path, n_frames=1, name="p.lvx"):
    frames = []
    for k in range(n_frames):
        pk = P.encode_data_packets(np.full((96, 3), 5.0), np.full(96, 9), 10**9 + k * 50_000_000, 240_000.0,
                                   data_type=2)
        frames.append([(2, pk[0])])
    write_lvx(tmp_path / name, frames, [AVIA])
    return tmp_path / name, 24 + 5 + 59 + 24   # first package


def test_a_timestamp_beyond_int64_is_a_packet_error_not_a_wrap():
    pk = bytearray(P.encode_data_packets(np.full((96, 3), 5.0), np.full(96, 9), 10**9, 240_000.0, data_type=2)[0])
    pk[10:18] = (0x7FFF_FFFF_FFFF_FFFF).to_bytes(8, "little")
    arr = np.frombuffer(bytes(pk), dtype=P.packet_dtype(2))
    with pytest.raises(P.PacketError, match="beyond any sensor clock"):
        P.decode_packets_array(arr, 240_000.0)


def test_a_package_stamped_0x7fff_is_named_in_the_lvx_and_in_replay(tmp_path):
    from foveatrack.replay import replay

    p, pkg = _file(tmp_path)
    data = bytearray(p.read_bytes())
    data[pkg + 11:pkg + 19] = (0x7FFF_FFFF_FFFF_FF00).to_bytes(8, "little")
    p.write_bytes(bytes(data))
    with pytest.raises(UserError, match=rf"package at byte {pkg}: field timestamp \(byte {pkg + 11}\)"):
        list(read_lvx(p))
    with pytest.raises(UserError, match="beyond any sensor clock"):
        replay(p)
