"""The simulator outputs what a Livox outputs: Cartesian int32 mm, turned into float64 metres by the
same operation as the live client's, so a simulated point and the point a client decodes from the
virtual lidar's packets are the same bits (the recording relies on it to store points exactly)."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from foveatrack.livox import protocol as P
from sim.loop import ClosedLoop
from sim.scene import load_scene

SCENES = Path(__file__).resolve().parents[2] / "scenes"


def test_mm_round_trip_and_the_one_operation():
    k = np.arange(-300_000, 300_001, 7, dtype=np.int32)
    m = P.mm_to_m(k)
    assert m.dtype == np.float64
    assert np.array_equal(P.m_to_mm(m), k)                       # metres -> mm recovers every k
    assert np.array_equal(P.quantise_to_mm_grid(m).view(np.int64), m.view(np.int64))   # idempotent
    # the product and the quotient differ in the last bit for some k: only the product is the client's
    assert np.any(m != k / 1000.0)
    assert np.array_equal(m.view(np.int64), (k * 1e-3).view(np.int64))


def test_rounding_is_to_the_nearest_mm_and_saturates():
    x = np.array([0.0004999, 0.0005001, -0.0015, 1.2345678, 3e6, -3e6])
    assert P.m_to_mm(x).tolist() == [0, 1, -2, 1235, 2**31 - 1, -(2**31)]


@pytest.mark.parametrize("data_type", [0, 2])
def test_simulated_points_are_the_live_clients_bits(data_type):
    scene = replace(load_scene(SCENES / "fig12-tracking.toml"), duration_s=0.3)
    loop = ClosedLoop(scene)
    frames = [loop.step(k * 0.1, (k + 1) * 0.1)[0] for k in range(3)]
    xyz = np.concatenate([f.xyz for f in frames])
    refl = np.concatenate([f.reflectivity for f in frames])
    assert len(xyz) > 1000 and not np.any(np.all(xyz == 0, axis=1))
    assert np.array_equal(P.quantise_to_mm_grid(xyz).view(np.int64), xyz.view(np.int64))   # on the grid
    # through the wire: what the virtual lidar sends, decoded as the daemon's client does
    datagrams = P.encode_data_packets(xyz, refl, 1_000_000_000, 100_000.0, data_type=data_type)
    batches = P.DataDecoder(point_rate_hz=100_000.0).decode(datagrams)
    live = np.concatenate([b.xyz for b in batches])
    assert live.shape == xyz.shape
    assert np.array_equal(live.view(np.int64), xyz.view(np.int64))
    assert np.array_equal(np.concatenate([b.reflectivity for b in batches]), refl)
