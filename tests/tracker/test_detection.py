import numpy as np
import pytest

from foveatrack.detection import detect_points, valid_points, wrap_deg
from foveatrack.space_of_interest import Box, Cylinder, Sector, space_from_mapping, BackgroundMap
from foveatrack.errors import UserError


def t(n):
    return np.arange(n, dtype=np.int64) * 1000


def test_no_points_and_only_invalid_points_give_none():
    assert detect_points(np.empty((0, 3)), t(0)) is None
    bad = np.array([[np.nan, 1, 1], [np.inf, 0, 0], [0, 0, 0], [1, -np.inf, 2]])
    assert detect_points(bad, t(4)) is None
    assert list(valid_points(bad)) == [False] * 4


def test_one_point_is_its_own_median_with_hand_bearing():
    d = detect_points(np.array([[3.0, 3.0, 0.0]]), np.array([5_000_000_000]))
    assert d.n_points == 1 and np.allclose(d.xyz, [3, 3, 0])
    assert d.az_deg == pytest.approx(45.0) and d.el_deg == pytest.approx(0.0)
    assert d.t_s == pytest.approx(5.0) and d.range_m == pytest.approx(np.sqrt(18))


def test_median_per_axis_ignores_outliers_and_invalid():
    pts = np.array([[10, 0, 1], [10.2, 0.1, 1.1], [9.8, -0.1, 0.9], [500, 80, -90],
                    [0, 0, 0], [np.nan, 0, 0]], float)
    d = detect_points(pts, t(6))
    # 4 valid points -> median of the two middle values on each axis (hand computed)
    assert np.allclose(d.xyz, [(10 + 10.2) / 2, (0 + 0.1) / 2, (0.9 + 1) / 2])  # z sorted: -90, 0.9, 1, 1.1
    assert d.n_points == 4
    assert d.t_s == pytest.approx(np.median([0, 1000, 2000, 3000]) * 1e-9)


def test_behind_sensor_and_overhead_bearings():
    d = detect_points(np.array([[-5.0, 1e-9, 0.0]]), t(1))
    assert d.az_deg == pytest.approx(180.0, abs=1e-6)
    d = detect_points(np.array([[-5.0, -5.0, 0.0]]), t(1))
    assert d.az_deg == pytest.approx(-135.0)
    d = detect_points(np.array([[-5.0, 0.0, 0.0]]), t(1))
    assert d.az_deg == 180.0                      # exactly behind: +180, never -180
    d = detect_points(np.array([[0.0, 0.0, 7.0]]), t(1))
    assert d.el_deg == 90.0 and d.az_deg == 0.0   # straight overhead: no division by x = 0
    assert wrap_deg(-180.0) == 180.0 and wrap_deg(540.0) == 180.0 and wrap_deg(-190.0) == 170.0


def test_spaces_of_interest():
    pts = np.array([[5, 0, 0], [50, 0, 0], [5, 5, 0], [-5, 0, 0], [5, 0, 3]], float)
    box = Box((0, -1, -1), (10, 1, 1))
    assert list(box.contains(pts)) == [True, False, False, False, False]
    cyl = Cylinder((5, 0), 1.0, -1, 1)
    assert list(cyl.contains(pts)) == [True, False, False, False, False]
    sec = Sector(az_min_deg=-10, az_max_deg=10, el_min_deg=-5, el_max_deg=5, r_min_m=1, r_max_m=20)
    assert list(sec.contains(pts)) == [True, False, False, False, False]
    behind = Sector(az_min_deg=170, az_max_deg=-170)          # wraps through 180
    assert list(behind.contains(pts)) == [False, False, False, True, False]
    d = detect_points(pts, t(5), box)
    assert d.n_points == 1 and np.allclose(d.xyz, [5, 0, 0])
    assert detect_points(pts, t(5), Box((100, 100, 100), (101, 101, 101))) is None


def test_space_from_mapping_validates():
    s = space_from_mapping({"kind": "sector", "r_min_m": 2, "r_max_m": 300}, "x")
    assert s.r_max_m == 300 and s.frame == "lidar"
    with pytest.raises(UserError, match="kind"):
        space_from_mapping({"kind": "sphere"}, "scene.toml [tracker.space]")
    with pytest.raises(UserError, match="unknown key.*'radius'"):
        space_from_mapping({"kind": "box", "min_xyz": [0, 0, 0], "max_xyz": [1, 1, 1], "radius": 3}, "x")
    with pytest.raises(UserError, match="min_xyz"):
        space_from_mapping({"kind": "box", "max_xyz": [1, 1, 1]}, "x")


def test_background_map_extension():
    bg = BackgroundMap(voxel_m=0.5, dilate=1)
    rng = np.random.default_rng(0)
    wall = np.column_stack([np.full(500, 10.0), rng.uniform(-5, 5, 500), rng.uniform(0, 3, 500)])
    bg.learn(wall)
    bg.freeze()
    pts = np.vstack([wall[:10], [[5.0, 0.0, 1.5]]])
    mask = bg.contains(pts)
    assert not mask[:10].any() and mask[10]
    d = detect_points(pts, t(11), bg)
    assert d.n_points == 1 and np.allclose(d.xyz, [5, 0, 1.5])


def test_median_of_rows_equals_numpys_median():
    from foveatrack.detection import _median_rows

    rng = np.random.default_rng(0)
    for n in range(1, 120):
        a = rng.normal(size=(n, 3)) * 10 ** rng.uniform(-3, 3)
        assert np.array_equal(_median_rows(a), np.median(a, axis=0)), n
        t = rng.integers(0, 10**17, n).astype(np.float64)   # timestamps [ns] as floats
        assert _median_rows(t) == np.median(t), n


def test_frozen_maker_builds_what_the_constructor_builds():
    import dataclasses
    import pickle

    from foveatrack.control import STOP
    from foveatrack.detection import Detection, frozen_maker
    from foveatrack.openloop.objects import FrameObject
    from foveatrack.sky.controller import SkyControlOutput
    from foveatrack.sky.tracks import SkyFrameOutput, SkyObject
    from foveatrack.tracker import TrackOutput, TrackState

    cases = [(Detection, (1.5, np.array([1.0, 2.0, 3.0]), 7, 63.4, 53.3, 3.74)),
             (FrameObject, (np.array([1.0, 2.0, 3.0]), 9, 0.4, 3.74, np.array([0.1, 0.2, 0.4]), 1.5e9)),
             (SkyObject, (np.array([1.0, 2.0, 3.0]), 1.5, 9, np.array([0.1, 0.2, 0.4]), True)),
             (SkyFrameOutput, (1.5, (), None, 120, 7, 1, (3,), ())),
             (SkyControlOutput, (None, None, 2, 3, (2,), {2: 0.5}, None)),
             (TrackOutput, (1.0, TrackState.TRACKING, None, STOP, 1.0, -2.0, 0.5, -1.0, 10.0, 2.0, 0.1, 0.2,
                            np.array([1.0, 2.0, 3.0]), 0.3, True))]
    for cls, args in cases:
        a, b = frozen_maker(cls)(*args), cls(*args)
        assert type(a) is cls and repr(a) == repr(b)
        for f in dataclasses.fields(cls):
            assert getattr(a, f.name) is getattr(b, f.name)
        with pytest.raises(dataclasses.FrozenInstanceError):
            a.t_s = 0.0
        assert repr(pickle.loads(pickle.dumps(a))) == repr(b)
        with pytest.raises(TypeError):
            frozen_maker(cls)(*args[:-1])
