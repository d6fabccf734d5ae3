import numpy as np
import pytest

from foveatrack.frames import Frame, FrameSlicer


def _stream(rng, n=5000, t_end_ns=1_234_567_891):
    t = np.sort(rng.integers(0, t_end_ns, n)).astype(np.int64)
    # put points exactly on boundaries too
    t[:20] = np.arange(20) * 100_000_000
    t = np.sort(t)
    xyz = rng.normal(size=(n, 3))
    return xyz, t


@pytest.mark.slow
@pytest.mark.parametrize("batch", [1, 7, 333, 5000])
def test_every_point_in_exactly_one_frame(batch):
    rng = np.random.default_rng(1)
    xyz, t = _stream(rng)
    s = FrameSlicer(10.0)
    frames = []
    for i in range(0, len(t), batch):
        frames += s.push(xyz[i:i + batch], t[i:i + batch])
    frames += s.flush()
    got_t = np.concatenate([f.t_ns for f in frames])
    assert np.array_equal(got_t, t)
    assert np.array_equal(np.concatenate([f.xyz for f in frames]), xyz)
    for f in frames:   # half-open intervals, contiguous, 100 ms
        assert np.all(f.t_ns >= round(f.t_start_s * 1e9)) and np.all(f.t_ns < round(f.t_end_s * 1e9))
        assert f.duration_s == pytest.approx(0.1)
    for a, b in zip(frames, frames[1:]):
        assert a.t_end_s == b.t_start_s


def test_points_out_of_order_within_a_frame_come_out_in_time_order():
    # Two packets of one frame arriving swapped, overlapping in time, with a tie (a pair of returns
    # is stamped alike): the frame's points come out sorted by time, ties in arrival order, with
    # their xyz and reflectivity; a stream already in order comes out as it went in.
    rng = np.random.default_rng(3)
    late = np.sort(rng.integers(30_000_000, 90_000_000, 50))
    early = np.sort(np.append(rng.integers(5_000_000, 60_000_000, 49), late[10]))
    nxt = np.sort(rng.integers(100_000_000, 250_000_000, 80))
    batches = [late, early, nxt]
    xyz = [rng.normal(size=(b.size, 3)) for b in batches]
    refl = [rng.integers(0, 255, b.size).astype(np.uint8) for b in batches]
    s = FrameSlicer(10.0)
    frames = []
    for b, x, r in zip(batches, xyz, refl):
        frames += s.push(x, b.astype(np.int64), r)
    frames += s.flush()
    t_all = np.concatenate(batches)
    order = np.argsort(t_all, kind="stable")
    assert np.array_equal(np.concatenate([f.t_ns for f in frames]), t_all[order])
    assert np.array_equal(np.concatenate([f.xyz for f in frames]), np.concatenate(xyz)[order])
    assert np.array_equal(np.concatenate([f.reflectivity for f in frames]), np.concatenate(refl)[order])
    s = FrameSlicer(10.0)
    frames = s.push(np.concatenate(xyz)[order], t_all[order], np.concatenate(refl)[order]) + s.flush()
    assert np.array_equal(np.concatenate([f.xyz for f in frames]), np.concatenate(xyz)[order])
    assert s.late_points == 0


def test_boundary_point_goes_to_later_frame_and_gaps_make_empty_frames():
    s = FrameSlicer(10.0)
    out = s.push(np.zeros((3, 3)) + 1, np.array([50_000_000, 100_000_000, 350_000_000]))
    assert [f.n_points for f in out] == [1, 1, 0]
    assert out[1].t_ns[0] == 100_000_000
    assert [f.n_points for f in s.flush()] == [1]


def test_late_points_are_counted_not_duplicated():
    s = FrameSlicer(10.0)
    s.push(np.ones((2, 3)), np.array([0, 250_000_000]))
    s.push(np.ones((1, 3)), np.array([10]))
    assert s.late_points == 1


def test_reflectivity_follows_points_and_frame_validates():
    s = FrameSlicer(20.0)
    fr = s.push(np.ones((3, 3)), np.array([0, 10, 60_000_000]), reflectivity=np.array([1, 2, 3], np.uint8))
    assert list(fr[0].reflectivity) == [1, 2]
    with pytest.raises(ValueError):
        Frame(0, 0.1, np.zeros((2, 3)), np.zeros(3, np.int64))
    with pytest.raises(ValueError):
        FrameSlicer(0.0)


def test_a_frame_holds_contiguous_arrays_whatever_it_was_given():
    """The tracker hands a frame's arrays to its box kernel as they are (no check per frame), so a
    Frame makes them contiguous: a Fortran-ordered or strided input is copied, values unchanged."""
    rng = np.random.default_rng(2)
    xyz_c = rng.normal(0, 10, (50, 3))
    t_c = np.arange(0, 100_000_000, 1_000_000, dtype=np.int64)[:50]
    for xyz, t_ns in ((np.asfortranarray(xyz_c), t_c), (xyz_c, np.repeat(t_c, 2)[::2]),
                      (np.hstack([xyz_c, xyz_c])[:, :3], t_c)):
        f = Frame(0.0, 0.1, xyz, t_ns)
        assert f.xyz.flags.c_contiguous and f.t_ns.flags.c_contiguous
        assert f.xyz.tobytes() == xyz_c.tobytes() and f.t_ns.tobytes() == t_c.tobytes()
