"""World kernels against their numpy twins, and exact-intersection properties."""

import math

import numpy as np
import pytest

from world_twins import cast_moving_twin, cast_static_twin, cast_straight_twin, rotate_twin
from sim.world import bodies
from sim.world import kernels as K


def _unit(rng, n):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def test_rotation_kernel_matches_matrix_twin_and_conventions():
    rng = np.random.default_rng(0)
    d = _unit(rng, 500)
    pan = rng.uniform(-np.pi, np.pi, 500)
    tilt = rng.uniform(-1.2, 1.2, 500)
    out = np.empty_like(d)
    K.rotate_pan_tilt_kernel(d, pan, tilt, out)
    np.testing.assert_allclose(out, rotate_twin(d, pan, tilt), atol=1e-14)
    # pan +90 deg turns the lidar's X (forward) to world +Y (left); tilt +90 deg turns it to +Z (up).
    x = np.array([[1.0, 0, 0]])
    for p, t, want in ((np.pi / 2, 0.0, [0, 1, 0]), (0.0, np.pi / 2, [0, 0, 1])):
        o = np.empty_like(x)
        K.rotate_pan_tilt_kernel(x, np.array([p]), np.array([t]), o)
        np.testing.assert_allclose(o[0], want, atol=1e-15)


@pytest.mark.parametrize("ripple", [False, True])
def test_head_pieces_rotation_is_the_exact_pose_at_every_point(ripple):
    # A real head model: commands inside the frame (piece boundaries between points), pan crossing
    # 180 deg at turbo.  The kernel must give the rotation by the head's exact pose at each point.
    from dataclasses import replace

    from gimbal.pelco import encode_pan_tilt
    from gimbal.pts303h import PTS303H, HeadParams

    params = HeadParams(ripple_rel=0.02 if ripple else 0.0)
    head = PTS303H(replace(params, history_s=100.0), unit_seed=5, pan0_deg=179.0, tilt0_deg=10.0)
    head.receive(encode_pan_tilt(1, 1, 0xFF, 1, 0x3F), [0.01 + 0.001 * i for i in range(7)])
    head.receive(encode_pan_tilt(1, -1, 0x20, -1, 0x10), [0.52 + 0.001 * i for i in range(7)])
    rng = np.random.default_rng(7)
    n = 20_000
    d = _unit(rng, n)
    t = np.sort(rng.uniform(0.4, 0.7, n))        # the second command takes effect in here
    pieces = head.pose_segments(0.4, 0.7)
    if ripple:
        assert pieces is None                     # then the loop asks the model point by point
        return
    assert pieces[0].shape[1] >= 2               # a piece boundary inside the window
    pan, tilt = head.angles_at(t, wrap_pan=False)
    assert pan.max() > 180.0                      # crossed the wrap, continuously
    out = np.empty_like(d)
    K.rotate_head_pieces_kernel(d, t, 0.4, 0.001, 301, pieces[0], pieces[1], out)
    np.testing.assert_allclose(out, rotate_twin(d, np.radians(pan), np.radians(tilt)), atol=1e-14)


def test_grid_rotation_matches_exact_rotation_of_interpolated_pose():
    rng = np.random.default_rng(1)
    n = 2000
    d = _unit(rng, n)
    t = np.sort(rng.uniform(0, 0.1, n))
    grid_t = np.arange(0, 0.1 + 0.0015, 0.001)
    pan_g = np.cumsum(rng.uniform(-0.0003, 0.0003, grid_t.size)) + 3.1  # crosses +pi: unwrapped
    tilt_g = np.cumsum(rng.uniform(-0.0003, 0.0003, grid_t.size)) + 0.3
    out = np.empty_like(d)
    K.rotate_pan_tilt_grid_kernel(d, t, 0.0, 0.001, pan_g, tilt_g, out)
    pan = np.interp(t, grid_t, pan_g)
    tilt = np.interp(t, grid_t, tilt_g)
    np.testing.assert_allclose(out, rotate_twin(d, pan, tilt), atol=1e-13)


def _scene_prims():
    return np.array([
        bodies.sphere((5, 1, 0), 0.7), bodies.box((6, -1, 0.5), (0.3, 0.5, 0.2), 0.4),
        bodies.disk((4, 0, -1), 0.5, (0.2, 0.1, 1.0)), bodies.plane((0, 0, -3), (0, 0, 1)),
        bodies.rect((8, 0, 0), (-1, 0, 0), (0, 1, 0), 2.0, 1.5),
    ])


def test_static_cast_matches_twin_for_every_primitive_kind():
    rng = np.random.default_rng(2)
    d = _unit(rng, 20_000)
    d[:, 0] = np.abs(d[:, 0]) + 0.2  # mostly forward, toward the primitives
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    prims = _scene_prims()
    r = np.full(len(d), np.inf)
    p = np.full(len(d), -1, dtype=np.int64)
    K.cast_static_kernel(d, prims, 0, r, p)
    rt, pt = cast_static_twin(d, prims)
    assert set(np.unique(p)) == {-1, 0, 1, 2, 3, 4}, "every kind is hit by some rays"
    assert np.array_equal(p, pt)
    finite = np.isfinite(r)
    np.testing.assert_allclose(r[finite], rt[finite], rtol=1e-12)
    # Cast after something nearer: only nearer hits replace it, and ids carry the offset.
    r2 = np.where(finite, r * 0.5, np.inf)
    p2 = np.where(finite, 99, -1)
    K.cast_static_kernel(d, prims, 7, r2, p2)
    assert np.all(p2[finite] == 99) and np.all(p2[~finite] == -1)
    r3 = np.full(len(d), np.inf)
    p3 = np.full(len(d), -1, dtype=np.int64)
    K.cast_static_kernel(d, prims, 7, r3, p3)
    assert np.array_equal(p3, np.where(p >= 0, p + 7, -1))


def _cast_one_by_one(d, prims, offset):
    """Each primitive alone (the kernel's plain per-primitive route), nearest kept in table order."""
    r = np.full(len(d), np.inf)
    p = np.full(len(d), -1, dtype=np.int64)
    for m in range(len(prims)):
        rm = np.full(len(d), np.inf)
        pm = np.full(len(d), -1, dtype=np.int64)
        K.cast_static_kernel(d, prims[m:m + 1], offset + m, rm, pm)
        nearer = rm < r
        r[nearer], p[nearer] = rm[nearer], pm[nearer]
    return r, p


@pytest.mark.parametrize("layout", ["room", "room after bodies", "room reversed", "wall pair + box"])
def test_room_and_opposed_walls_cast_like_each_rectangle_alone(layout):
    # Opposed rectangles with the origin between them are tested one per ray (the one it heads
    # for); the result must be the same, to the bit, as every rectangle tested: also on rays along
    # the axes and through the room's edges and corners, where a wall's in-rectangle test rounds.
    rng = np.random.default_rng(11)
    size, centre = np.array([60.0, 40.0, 8.0]), np.array([20.0, 0.0, 2.5])
    room = np.array(bodies.room(size, centre))
    prims = {"room": room,
             "room after bodies": np.vstack([np.array([bodies.sphere((3, 1, 0), 0.5),
                                                       bodies.box((5, -1, 0), (0.3, 0.4, 0.2), 0.3)]), room]),
             "room reversed": room[::-1].copy(),
             "wall pair + box": np.vstack([room[2:4], np.array([bodies.box((4, 0, 0), (0.2, 0.2, 0.2), 0.1)])]),
             }[layout]
    corners = centre + size / 2 * np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    edges = (corners[:, None, :] + corners[None, :, :]).reshape(-1, 3) / 2
    d = np.vstack([_unit(rng, 20_000), np.eye(3), -np.eye(3), corners, edges])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = np.full(len(d), np.inf)
    p = np.full(len(d), -1, dtype=np.int64)
    K.cast_static_kernel(d, prims, 5, r, p)
    r1, p1 = _cast_one_by_one(d, prims, 5)
    assert np.array_equal(r, r1) and np.array_equal(p, p1)
    if layout.startswith("room"):
        assert np.all(p >= 0), "from inside a closed room every ray hits something"
    rt, pt = cast_static_twin(d, prims)
    assert np.array_equal(np.where(p >= 0, p - 5, -1), pt)
    np.testing.assert_allclose(r[pt >= 0], rt[pt >= 0], rtol=1e-12)


def test_walls_not_around_the_origin_are_cast_one_by_one():
    # Both walls of a pair on one side of the origin (a building seen from outside): either can be
    # hit, the nearer one wins.
    near = bodies.rect((10, 0, 0), (-1, 0, 0), (0, 1, 0), 2.0, 2.0)
    far = bodies.rect((20, 0, 0), (1, 0, 0), (0, 1, 0), 8.0, 8.0)
    d = np.array([[1.0, 0.0, 0.0], [0.9, 0.3, 0.0], [0.99, 0.0, 0.14]])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = np.full(len(d), np.inf)
    p = np.full(len(d), -1, dtype=np.int64)
    K.cast_static_kernel(d, np.array([near, far]), 0, r, p)
    assert list(p) == [0, 1, 0]
    np.testing.assert_allclose(r, [10.0, 20.0 / d[1, 0], 10.0 / d[2, 0]], rtol=1e-15)


def test_hit_points_lie_on_the_surfaces():
    rng = np.random.default_rng(3)
    d = _unit(rng, 20_000)
    d[:, 0] = np.abs(d[:, 0]) + 0.2
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    prims = _scene_prims()
    r = np.full(len(d), np.inf)
    p = np.full(len(d), -1, dtype=np.int64)
    K.cast_static_kernel(d, prims, 0, r, p)
    x = d * np.where(np.isfinite(r), r, 0)[:, None]
    sph = p == 0
    np.testing.assert_allclose(np.linalg.norm(x[sph] - prims[0, 1:4], axis=1), 0.7, atol=1e-12)
    pl = p == 3
    np.testing.assert_allclose(x[pl, 2], -3.0, atol=1e-12)


def test_rays_parallel_to_a_plane_or_away_from_it_miss_it():
    # The plane loop divides before it tests the denominator: den = 0 must give a miss, not an error.
    prims = np.array([bodies.ground(1.5)])
    d = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.6, 0.0, -0.8], [0.0, 0.0, -1.0]])
    r = np.full(len(d), np.inf)
    p = np.full(len(d), -1, dtype=np.int64)
    K.cast_static_kernel(d, prims, 4, r, p)
    assert list(p) == [-1, -1, -1, 4, 4]
    np.testing.assert_allclose(r[3:], [1.5 / 0.8, 1.5], rtol=1e-15)
    rt, pt = cast_static_twin(d, prims)
    np.testing.assert_array_equal(np.where(pt >= 0, pt + 4, -1), p)


def test_moving_body_cast_matches_twin():
    rng = np.random.default_rng(4)
    quad = bodies.quadrotor()
    n = 20_000
    pos = np.column_stack([np.full(n, 10.0), rng.uniform(-0.2, 0.2, n), rng.uniform(-0.2, 0.2, n)])
    target = pos + rng.normal(0, 0.12, (n, 3))
    d = target / np.linalg.norm(target, axis=1, keepdims=True)
    yaw = rng.uniform(-np.pi, np.pi, n)
    r = np.full(n, np.inf)
    p = np.full(n, -1, dtype=np.int64)
    K.cast_moving_kernel(np.arange(n, dtype=np.int64), d, pos, yaw, quad.prims, 0, r, p)
    rt, pt = cast_moving_twin(d, pos, yaw, quad.prims)
    assert (p >= 0).mean() > 0.1 and len(set(p[p >= 0])) >= 5, "body, arms and rotors are all hit"
    assert np.array_equal(p, pt)
    f = np.isfinite(r)
    np.testing.assert_allclose(r[f], rt[f], rtol=1e-12)


def test_straight_passes_cast_together_are_each_cast_on_its_own():
    """cast_straight_kernel: the ranges and ids of cast_moving_kernel body by body (each at its
    Straight.position at its rays' times, the yaw of its velocity), bodies overlapping (a ray may
    meet two: the first cast keeps a tie) and some rays already nearer; and its numpy twin's."""
    from sim.world.trajectories import Straight, heading_rad

    rng = np.random.default_rng(8)
    quads = [bodies.quadrotor(s) for s in (0.35, 0.5, 0.3, 0.35)]
    prims = np.concatenate([q.prims for q in quads])
    prim_start = np.cumsum([0] + [q.prims.shape[0] for q in quads])
    paths = [Straight(tuple(rng.uniform(-3, 3, 3) + [20.0, 0, 0]), tuple(rng.normal(size=3) * 5)) for _ in quads]
    paths[2] = paths[0]             # two bodies on one pass: every ray that meets one meets both
    start_m = np.array([p._start for p in paths])
    velocity = np.array([p._velocity for p in paths])
    yaw = heading_rad(velocity)
    n = 8000
    t_ray = np.sort(rng.uniform(1.0, 1.1, n))
    aim = np.array([p.position(t_ray[i:i + 1])[0] for i, p in zip(range(n), [paths[k % 4] for k in range(n)])])
    d = aim + rng.normal(0, 0.2, (n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    order = np.array([3, 0, 1, 2])      # cast in this order; body k's rays idx[start[k]:start[k + 1]]
    per = [np.sort(rng.choice(n, int(rng.integers(2000, 4000)), replace=False)) for _ in order]
    idx = np.concatenate(per)
    start = np.cumsum([0] + [p.size for p in per])
    r, p = np.full(n, np.inf), np.full(n, -1, dtype=np.int64)
    r[::5], p[::5] = 19.0, 99
    r1, p1, r2, p2 = r.copy(), p.copy(), r.copy(), p.copy()
    K.cast_straight_kernel(idx, start, order, d, t_ray, start_m, velocity, yaw, prims, prim_start, r1, p1)
    for k in order:
        rays = idx[start[k]:start[k + 1]]
        K.cast_moving_kernel(rays, d, paths[k].position(t_ray[rays]), np.full(rays.size, yaw[k]),
                             quads[k].prims, prim_start[k], r2, p2)
    assert np.array_equal(r1, r2) and np.array_equal(p1, p2)
    assert len(set(p1[(p1 >= 0) & (p1 != 99)])) > 20
    t_ns = np.sort(rng.integers(1_000_000_000, 1_100_000_000, n))    # times in ns: t_ns * 1e-9 formed inside
    r3, p3, r4, p4 = r.copy(), p.copy(), r.copy(), p.copy()
    K.cast_straight_kernel(idx, start, order, d, t_ns, start_m, velocity, yaw, prims, prim_start, r3, p3)
    K.cast_straight_kernel(idx, start, order, d, t_ns * 1e-9, start_m, velocity, yaw, prims, prim_start, r4, p4)
    assert np.array_equal(r3, r4) and np.array_equal(p3, p4)
    rt, pt = cast_straight_twin(d, idx, start, order, t_ray, start_m, velocity, yaw, prims, prim_start, r, p)
    assert np.array_equal(p1, pt)
    f = np.isfinite(r1)
    np.testing.assert_allclose(r1[f], rt[f], rtol=1e-12)


def test_cone_cull_keeps_every_ray_that_can_hit():
    rng = np.random.default_rng(5)
    d = _unit(rng, 50_000)
    c = np.array([6.0, 1.0, 0.5])
    status = (rng.random(len(d)) < 0.1).astype(np.uint8)    # 10 % of the rays failed in the prisms
    idx = np.empty(len(d), dtype=np.int64)
    k = K.cone_candidates_kernel(d, status, *c, 0.8, idx)
    mark = np.zeros(len(d), dtype=bool)
    mark[idx[:k]] = True
    assert np.all(np.diff(idx[:k]) > 0), "in ray order"
    r = np.full(len(d), np.inf)
    p = np.full(len(d), -1, dtype=np.int64)
    K.cast_static_kernel(d, np.array([bodies.sphere(c, 0.8)]), 0, r, p)
    assert np.all(mark[(p >= 0) & (status == 0)]), "no valid ray that hits the bounding sphere is culled"
    assert not mark[status != 0].any(), "failed rays are never candidates"
    assert 0 < mark.mean() < 0.01


def test_quadrotor_size_and_bound():
    q = bodies.quadrotor(0.35)
    assert 0.3 < 2 * q.bounding_radius_m < 0.6
    assert math.isinf(bodies.Body("g", np.array([bodies.plane((0, 0, 0), (0, 0, 1))]), np.ones(1)).bounding_radius_m)
