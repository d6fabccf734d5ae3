"""The clustering kernel against its plain-numpy twin, and what clusters are."""

import numpy as np
import pytest

from cluster_twin import cluster_labels_numpy
from foveatrack.openloop.objects import cluster_labels


@pytest.mark.parametrize("seed", range(8))
def test_kernel_equals_numpy_twin(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 400))
    # blobs near and far, and scattered points, so that both gap terms (metres, range) decide links
    centres = rng.uniform(-300, 300, size=(5, 3))
    centres[:2] *= 0.01
    pts = np.vstack([c + rng.normal(0, rng.uniform(0.05, 2.0), size=(n // 6 + 1, 3)) for c in centres]
                    + [rng.uniform(-400, 400, size=(n // 6 + 1, 3))])
    for tol_m, tol_rad in ((0.5, 0.01), (0.2, 0.0), (1.0, 0.05)):
        got, k = cluster_labels(pts, tol_m, tol_rad)
        want, kw = cluster_labels_numpy(pts, tol_m, tol_rad)
        assert k == kw
        np.testing.assert_array_equal(got, want)


def test_gap_grows_with_range():
    # two points 2 m apart: one cluster at 300 m (0.01 rad * 300 m = 3 m gap), two at 3 m
    near = np.array([[3.0, 0, 0], [3.0, 2.0, 0]])
    far = np.array([[300.0, 0, 0], [300.0, 2.0, 0]])
    assert cluster_labels(near, 0.5, 0.01)[1] == 2
    assert cluster_labels(far, 0.5, 0.01)[1] == 1


def test_chains_link_and_labels_follow_first_points():
    pts = np.array([[10.0, 0, 0], [50.0, 0, 0], [10.4, 0, 0], [10.8, 0, 0], [50.3, 0, 0]])
    labels, k = cluster_labels(pts, 0.5, 0.0)
    assert k == 2
    np.testing.assert_array_equal(labels, [0, 1, 0, 0, 1])


def test_points_too_far_apart_for_cube_numbers_take_every_pair():
    # cubes of 1 mm over +-1e7 m do not fit an int64: the kernel tests every pair, with the same result
    rng = np.random.default_rng(11)
    pts = np.vstack([rng.normal(0, 0.001, size=(20, 3)), [[1e7, -1e7, 1e7], [-1e7, 1e7, -1e7]],
                     rng.normal(5, 0.001, size=(20, 3))])
    got, k = cluster_labels(pts, 0.002, 0.0)
    want, kw = cluster_labels_numpy(pts, 0.002, 0.0)
    assert k == kw
    np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("seed", range(4))
def test_points_on_cube_boundaries_link_across_them(seed):
    # points on a grid of exactly the cube size: every link crosses a cube face
    rng = np.random.default_rng(100 + seed)
    g = np.arange(-6, 7) * 0.5
    pts = np.array(np.meshgrid(g, g, g[:3], indexing="ij")).reshape(3, -1).T
    pts = pts[rng.random(len(pts)) < 0.5]
    got, k = cluster_labels(pts, 0.5, 0.0)
    want, kw = cluster_labels_numpy(pts, 0.5, 0.0)
    assert k == kw
    np.testing.assert_array_equal(got, want)


def test_cluster_summaries_equal_numpy_medians_bit_for_bit():
    from cluster_twin import objects_from_labels_numpy
    from foveatrack.openloop.objects import objects_from_labels

    rng = np.random.default_rng(4)
    sizes = set()
    for trial in range(20):
        pts = np.concatenate([rng.normal(size=(int(k), 3)) * rng.uniform(0.05, 2.0) + rng.uniform(-40, 40, 3)
                              for k in rng.integers(1, 30, rng.integers(1, 12))])
        if trial % 4 == 0:
            pts = np.round(pts, 1)                          # ties: equal values in a cluster
        t_ns = rng.integers(0, 10**8, pts.shape[0]) + 10**12
        labels, k = cluster_labels(pts, 0.8, 0.0)
        for min_points, max_ext in ((1, np.inf), (2, 3.0), (5, np.inf)):
            got, kept = objects_from_labels(pts, labels, k, min_points, max_ext, t_ns)
            want, kept_w = objects_from_labels_numpy(pts, labels, k, min_points, max_ext, t_ns)
            assert kept == kept_w
            for g, (m, n, e, sides, t) in zip(got, want):
                assert g.xyz_m.tobytes() == m.tobytes() and g.n_points == n and g.extent_m == e
                assert g.sides_m.tobytes() == sides.tobytes()
                assert g.t_median_ns == t
                sizes.add(n)
            untimed, _ = objects_from_labels(pts, labels, k, min_points, max_ext)     # the open-loop tracker's call
            assert [(o.xyz_m.tobytes(), o.t_median_ns) for o in untimed] == [(o.xyz_m.tobytes(), None) for o in got]
    assert {n % 2 for n in sizes} == {0, 1} and max(sizes) > 20, "odd and even counts, small and large"
