"""Points of formats 3 and 4: exact and compact when they are on the Livox mm grid, exact float64 otherwise.

x, y, z on the mm grid are stored as the float32 multiple of 2^-11 m nearest to the point; the reader
takes k = rint(1000 v) [mm] and returns the client's k * 1e-3.  Point times (format 4) as int32
``age_ns``, the frame time - the point time."""

import numpy as np
import pytest

from foveatrack.livox.protocol import m_to_mm, mm_to_m
from foveatrack.recording import RecordingReader, RecordingWriter
from foveatrack.recording.format import MAX_GRID_MM, mm_grid_f32, mm_grid_to_m


def _all_mm_round_trip(lo: int, hi: int) -> None:
    for a in range(lo, hi, 1 << 21):
        k = np.arange(a, min(a + (1 << 21), hi), dtype=np.int32)
        m = mm_to_m(k)
        v = mm_grid_f32(np.stack([m, m, m], 1))
        assert v is not None and v.dtype == np.float32
        assert np.abs(v[:, 0].astype(np.float64) - m).max() <= 2.0**-12          # within 0.25 mm
        back = mm_grid_to_m(v[:, 0])
        assert np.array_equal(back.view(np.int64), m.view(np.int64)), a


def test_every_mm_within_500_m_round_trips_to_the_bit():
    _all_mm_round_trip(-500_000, 500_001)


@pytest.mark.slow
def test_every_mm_up_to_the_bound_round_trips_to_the_bit():
    _all_mm_round_trip(-MAX_GRID_MM + 1, MAX_GRID_MM)


def test_past_the_bound_or_off_the_grid_there_is_no_grid_encoding():
    assert mm_grid_f32(np.array([[MAX_GRID_MM * 1e-3, 0.0, 0.0]])) is None
    assert mm_grid_f32(np.array([[(MAX_GRID_MM - 1) * 1e-3, 0.0, 0.0]])) is not None
    assert mm_grid_f32(np.array([[1.2345678, 0.0, 0.0]])) is None          # not a mm value
    assert mm_grid_f32(np.array([[1.234, 0.0, 0.0]])) is not None
    # 1.234 written as 1234 / 1000 is not the client's 1234 * 1e-3 for every k: only the latter is on the grid
    k = np.arange(1, 100_000, dtype=np.int32)
    off = k[(k / 1000.0) != mm_to_m(k)]
    assert off.size and mm_grid_f32(np.stack([off / 1000.0] * 3, 1)) is None


def _frames(on_grid: bool, far: bool = False, n=3000):
    rng = np.random.default_rng(5)
    out = []
    for k in range(4):
        t = 2_000_000_000 + k * 100_000_000
        xyz = rng.normal(0, 60, (n, 3))
        if far:
            xyz[7] = (9000.0, 1.0, 2.0)
        if on_grid:
            xyz = mm_to_m(m_to_mm(xyz))
        tp = t - 100_000_000 + np.sort(rng.choice(10_000, n, replace=False)).astype(np.int64) * 10_000
        out.append((t, xyz, tp, rng.integers(0, 151, n).astype(np.uint8)))
    return out


@pytest.mark.parametrize("on_grid,far", [(True, False), (False, False), (True, True)])
def test_frames_come_back_to_the_bit(tmp_path, on_grid, far):
    frames = _frames(on_grid, far)
    p = tmp_path / "r.mcap"
    with RecordingWriter(p, {}) as w:
        for k, (t, xyz, tp, refl) in enumerate(frames):
            w.write_points(t, k, xyz, tp, refl)
    got = list(RecordingReader(p).points())
    for f, (t, xyz, tp, refl) in zip(got, frames, strict=True):
        assert np.array_equal(f.xyz.view(np.int64), xyz.view(np.int64))
        assert np.array_equal(f.t_ns_points, tp) and np.array_equal(f.reflectivity, refl)
    # the grid encoding is what makes the file small: about 15 bytes a point against 26-28
    per_point = p.stat().st_size / sum(len(f) for f in got)
    assert (per_point < 17) == (on_grid and not far)


def test_float32_refuses_points_past_the_bound(tmp_path):
    t, xyz, tp, refl = _frames(True, far=True)[0]
    with RecordingWriter(tmp_path / "r.mcap", {}, points_dtype="float32") as w:
        with pytest.raises(ValueError, match="8192 m"):
            w.write_points(t, 0, xyz, tp, refl)


@pytest.mark.parametrize("case", ["grid", "off-grid", "far", "nan", "empty", "one", "same-time", "after-end"])
def test_pack_kernel_gives_the_numpy_twins_bytes(case):
    from foveatrack.recording.format import pack_points_numpy
    from foveatrack.recording.pack_kernels import pack_points

    rng = np.random.default_rng(11)
    n = {"empty": 0, "one": 1}.get(case, 2500)
    xyz = rng.normal(0, 80, (n, 3))
    if case != "off-grid":
        xyz = mm_to_m(m_to_mm(xyz))
    if case == "far":
        xyz[-1, 1] = MAX_GRID_MM * 1e-3
    if case == "nan":
        xyz[3, 2] = np.nan
    t = 7_000_000_000
    tp = t - np.sort(rng.choice(100_000, n, replace=False)).astype(np.int64) * 1_003
    if case == "same-time":
        tp[:] = t - 5_000_000
    if case == "after-end":         # a writer may give points up to 2.1 s either side of the frame time
        tp[0] = t + 2**31 - 1
        tp[1] = t - 2**31 + 1
    refl = rng.integers(0, 256, n).astype(np.uint8)
    a = pack_points(xyz, t, tp, refl)
    b = pack_points_numpy(xyz, t - tp, refl)
    assert a.dtype == b.dtype and a.tobytes() == b.tobytes()
    expect_f32 = case in ("grid", "empty", "one", "same-time", "after-end")
    assert (a.dtype["x"] == np.float32) == expect_f32
    assert a.dtype["age_ns"] == np.int32 and np.array_equal(t - a["age_ns"].astype(np.int64), tp)
