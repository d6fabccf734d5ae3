"""The sky besides the drones (sim.world.sky, sim.scene_sky): birds, flocks, swaying trees, stray near
returns, several drones, and the truth of every object in the recording."""

from __future__ import annotations

import copy
import math
import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from foveatrack.errors import UserError
from sim.loop import ClosedLoop
from sim.scene import load_scene, scene_from_mapping
from sim.world import kernels as K
from sim.world import sky
from world_twins import (bodies_candidates_twin, bout_index_twin, cast_flapping_twin, cast_flock_twin,
                         cone_candidates_twin, flock_candidates_twin, flock_positions_twin, flock_velocities_twin,
                         flock_wing_angles_twin, moving_cull_twin, ray_blocks_twin)

SCENES = Path(__file__).resolve().parents[2] / "scenes"
NEW_SCENES = ("two-drones-crossing", "drone-and-flock", "drone-tree-line", "swarm-of-five")


def _mapping(name: str) -> dict:
    return tomllib.loads((SCENES / f"{name}.toml").read_text())


# ---------------------------------------------------------------------------------------- the kernel

def test_flapping_cast_matches_numpy_twin():
    rng = np.random.default_rng(8)
    bird = sky.bird_body(0.9)
    n = 20_000
    pos = np.column_stack([np.full(n, 9.0), rng.uniform(-0.1, 0.1, n), rng.uniform(-0.1, 0.1, n)])
    aim = pos + rng.normal(0, 0.3, (n, 3))
    d = aim / np.linalg.norm(aim, axis=1, keepdims=True)
    yaw = rng.uniform(-np.pi, np.pi, n)
    flap = rng.uniform(-0.6, 1.2, n)
    r = np.full(n, np.inf)
    p = np.full(n, -1, dtype=np.int64)
    K.cast_flapping_kernel(np.arange(n, dtype=np.int64), d, pos, yaw, flap, bird.body.prims, bird.hinge, 0, r, p)
    rt, pt = cast_flapping_twin(d, pos, yaw, flap, bird.body.prims, bird.hinge)
    assert set(p[p >= 0]) == {0, 1, 2}, "body and both wings are hit"
    assert np.array_equal(p, pt)
    f = np.isfinite(r)
    np.testing.assert_allclose(r[f], rt[f], rtol=1e-12)


def test_a_raised_wing_is_where_the_hinge_puts_it():
    # Wings up 90 deg: a ray straight down through where the left wing's middle would be at rest
    # misses it, and a ray at the raised wing's middle hits it at the expected range.
    bird = sky.bird_body(1.0)
    b, half_w = 1.0, 0.06
    y_mid = half_w + (b / 2 - half_w) / 2
    pos = np.array([[0.0, 0.0, -10.0]])
    one = np.array([0], dtype=np.int64)

    def cast(d, phi):
        r, p = np.array([np.inf]), np.array([-1], dtype=np.int64)
        K.cast_flapping_kernel(one, np.array([d]) / np.linalg.norm(d), pos, np.zeros(1), np.array([phi]),
                               bird.body.prims, bird.hinge, 0, r, p)
        return r[0], p[0]

    assert cast(np.array([0.0, y_mid, -10.0]), 0.0)[1] == 1
    assert cast(np.array([0.0, y_mid, -10.0]), math.pi / 2)[1] == -1
    # raised, the wing stands on its hinge (0, 0.06, 0.03) and reaches up 0.44 m, its 15 mm thickness
    # now along y: a ray from the origin toward -y, the bird 5 m away with the wing's middle at the
    # ray's height, meets its face at 5 - 0.06 - 0.0075 m (the body lies below the ray)
    rr, pp = np.array([np.inf]), np.array([-1], dtype=np.int64)
    K.cast_flapping_kernel(one, np.array([[0.0, -1.0, 0.0]]), np.array([[0.0, -5.0, -0.25]]), np.zeros(1),
                           np.array([math.pi / 2]), bird.body.prims, bird.hinge, 0, rr, pp)
    assert pp[0] == 1 and abs(rr[0] - (5.0 - half_w - 0.0075)) < 1e-9


# ---------------------------------------------------------------------------------------- birds

def test_wingbeat_follows_pennycuick_and_falls_with_wingspan():
    assert 12.5 < sky.wingbeat_hz(0.2) < 15.0
    assert 5.5 < sky.wingbeat_hz(0.65) < 7.5
    assert 3.5 < sky.wingbeat_hz(1.5) < 4.5
    spans = np.linspace(0.2, 1.5, 30)
    assert np.all(np.diff([sky.wingbeat_hz(b) for b in spans]) < 0)


def test_flap_schedule_glides_the_share_asked_and_flaps_whole_beats():
    rng = np.random.default_rng(3)
    f = sky.wingbeat_hz(0.5)
    s = sky.flap_schedule(rng, f, 600.0, 0.4)
    t = np.arange(0.0, 600.0, 0.01)
    assert abs((~s.flapping(t)).mean() - 0.4) < 0.07
    # every flapping bout lasts whole wingbeats: the wing is back at the glide angle when it ends
    ends = s.bout_start_s[1:][s.bout_flaps[:-1]]
    np.testing.assert_allclose(s.angle_rad(ends - 1e-9), s.phi0_rad, atol=1e-6)
    assert sky.flap_schedule(rng, f, 10.0, 1.0).flapping(t[:1000]).sum() == 0
    assert sky.flap_schedule(rng, f, 10.0, 0.0).flapping(t[:1000]).all()


def _resolved_hit_counts(glide_fraction: float, wingspan_m: float, duration_s: float = 4.0, step_s: float = 0.002):
    """Rays that hit a bird flying straight over the lidar (12 m up, 5 m/s), seen from below by a
    fovea that resolves it: every ``step_s`` a 48 x 48 raster of rays 2.5 cm apart at its height,
    centred on it, through the sensor's own casting path (:class:`sim.sensor.SceneSensor`)."""
    from sim.scan.model import ScanChunk
    from sim.sensor import SceneSensor

    scene = scene_from_mapping({
        "scene": {"name": "bird-overhead", "duration_s": duration_s, "seed": 5},
        "bird": [{"id": "b", "wingspan_m": wingspan_m, "glide_fraction": glide_fraction,
                  "trajectory": {"type": "straight", "start_m": [-10.0, 0.0, 12.0], "velocity_m_s": [5.0, 0.0, 0.0]}}],
    })
    sensor = SceneSensor(scene)
    bird = scene.others[0]
    g = (np.arange(48) - 23.5) * 0.025 * wingspan_m / 0.6
    gx, gy = (a.ravel() for a in np.meshgrid(g, g))
    counts = []
    times = np.arange(0.0, duration_s, step_s)
    for t0 in np.arange(0.0, duration_s, 0.1):        # one sensor call per 100 ms, as the loop makes
        ts = times[(times >= t0 - 1e-12) & (times < t0 + 0.1 - 1e-12)]
        t_ns = np.repeat(np.round(ts * 1e9).astype(np.int64), gx.size)
        c = bird.trajectory.position(ts)
        aim = np.column_stack([np.repeat(c[:, 0], gx.size) + np.tile(gx, ts.size),
                               np.repeat(c[:, 1], gx.size) + np.tile(gy, ts.size), np.repeat(c[:, 2], gx.size)])
        d = aim / np.linalg.norm(aim, axis=1, keepdims=True)
        chunk = ScanChunk(0, t_ns, d, np.zeros(t_ns.size, np.uint8), np.zeros(t_ns.size, np.uint8))
        xyz, pt_ns, _, _ = sensor.returns(chunk, d, t0, t0 + 0.1)
        counts.append(np.bincount(np.searchsorted(ts, pt_ns * 1e-9 - 1e-12), minlength=ts.size))
    return times, np.concatenate(counts)


def _peak_hz(counts, step_s):
    c = (counts - counts.mean()) * np.hanning(counts.size)
    n = 16 * counts.size                           # zero-padded: the peak to a small part of a bin
    power = np.abs(np.fft.rfft(c, n)) ** 2
    freq = np.fft.rfftfreq(n, step_s)
    band = (freq > 1.0) & (freq < 40.0)
    return freq[band][np.argmax(power[band])], freq, power


@pytest.mark.parametrize("wingspan_m", [0.3, 1.4])
def test_bird_flapping_period_is_seen_in_the_hit_count(wingspan_m):
    """A resolved bird flapping all the time: its hit count rises and falls at its wingbeat
    frequency (the wings' area seen from below follows cos phi); gliding, that frequency is absent
    (the count changes only slowly, as the bird is seen more or less obliquely)."""
    f_beat = sky.wingbeat_hz(wingspan_m)
    _, counts = _resolved_hit_counts(0.0, wingspan_m)
    assert counts.min() > 50, "the bird is resolved: dozens of rays on it at every step"
    peak, freq, power = _peak_hz(counts, 0.002)
    assert abs(peak - f_beat) < 0.1, (peak, f_beat)
    _, glide = _resolved_hit_counts(1.0, wingspan_m)
    _, _, power_glide = _peak_hz(glide, 0.002)
    near = np.abs(freq - f_beat) < 0.3
    assert power_glide[near].max() < 0.01 * power[near].max(), "gliding, the wingbeat is not in the count"


def test_flock_birds_keep_apart_and_fly_at_bird_speeds():
    scene = load_scene(SCENES / "drone-and-flock.toml")
    birds = [o for o in scene.others if o.cls == "bird"]
    assert len(birds) == 20 and len({o.id for o in birds}) == 20
    t = np.linspace(0.0, scene.duration_s, 201)
    pos = np.stack([o.trajectory.position(t) for o in birds])          # (20, T, 3)
    speed = np.linalg.norm(np.stack([o.trajectory.velocity(t) for o in birds]), axis=2)
    assert 5.0 <= speed.min() and speed.max() <= 20.0
    gaps = np.linalg.norm(pos[:, None] - pos[None, :], axis=3)
    gaps[np.arange(20), np.arange(20)] = np.inf
    assert gaps.min() > 0.6, "two birds of the flock stay a wingspan apart"
    assert 0.6 * 0.9 - 1e-9 <= min(o.size_m for o in birds) and max(o.size_m for o in birds) <= 0.6 * 1.1 + 1e-9


def test_a_flock_s_poses_together_are_each_bird_s_own_to_the_bit():
    scene = load_scene(SCENES / "drone-and-flock.toml")
    runs = sky.FlockPoses.groups(scene.others)
    assert len(runs) == 1 and runs[0][1] - runs[0][0] == 20
    birds = scene.others[runs[0][0]:runs[0][1]]
    flock = sky.FlockPoses(birds)
    rng = np.random.default_rng(3)
    m = np.sort(rng.integers(0, 20, 3000))
    t = rng.uniform(-0.5, scene.duration_s + 0.5, m.size)
    # bout starts hit exactly, and times before a bird's first bout
    t[:20] = [b.flap.bout_start_s[min(1, b.flap.bout_start_s.size - 1)] for b in birds]
    m[:20] = np.arange(20)
    t[20:40] = -5.0
    order = np.argsort(m, kind="stable")
    m, t = m[order], t[order]
    pos, yaw = flock.poses(m, t)
    wings = flock.wing_angles(m, t)
    both = flock.positions_velocities(m, t)
    for k, b in enumerate(birds):
        rows = m == k
        assert np.array_equal(pos[rows], b.trajectory.position(t[rows]))
        assert np.array_equal(both[0][rows], pos[rows])
        assert np.array_equal(both[1][rows], b.trajectory.velocity(t[rows]))
        assert np.array_equal(flock.velocities(m[rows], t[rows]), b.trajectory.velocity(t[rows]))
        assert np.array_equal(yaw[rows], sky.body_yaw_rad(b.trajectory, t[rows]))
        assert np.array_equal(wings[rows], b.flap.angle_rad(t[rows]))


def test_flock_groups_are_runs_of_one_flock_s_flapping_birds():
    a = list(load_scene(SCENES / "drone-and-flock.toml").others)
    crowns = [o for o in load_scene(SCENES / "drone-tree-line.toml").others if o.cls == "tree"]
    assert sky.FlockPoses.groups(crowns) == []
    assert sky.FlockPoses.groups(a[:5] + crowns[:1] + a[5:7] + a[7:8]) == [(0, 5), (6, 9)]
    assert sky.FlockPoses.groups(a[:1]) == [], "a lone bird is cast on its own"


def test_wing_phase_kernel_finds_numpy_s_bouts():
    rng = np.random.default_rng(11)
    starts = [np.sort(rng.uniform(-1.0, 10.0, k)) for k in (1, 2, 7, 30)]
    member = rng.integers(0, 4, 5000)
    t = rng.uniform(-2.0, 11.0, member.size)
    t[:4] = [s[-1] for s in starts]
    member[:4] = np.arange(4)
    sizes = np.array([s.size for s in starts])
    bout, phase = np.empty(t.size, np.int64), np.empty(t.size)
    two_pi_f = rng.uniform(20.0, 80.0, 4)
    cat = np.concatenate(starts)
    K.wing_phase_kernel(t, member, np.cumsum(sizes) - sizes, np.cumsum(sizes), cat, two_pi_f, bout, phase)
    assert np.array_equal(bout, bout_index_twin(t, member, starts))
    assert np.array_equal(phase, two_pi_f[member] * (t - cat[bout]))


def _flocks():
    """drone-and-flock's 20 birds on a circle, and flocks on a straight line and a manual (spline) path."""
    flocks = [sky.FlockPoses(load_scene(SCENES / "drone-and-flock.toml").others)]
    m = _mapping("drone-and-flock")
    for trajectory in ({"type": "straight", "start_m": [40.0, 10.0, 8.0], "velocity_m_s": [0.0, -7.0, 0.0]},
                       {"type": "manual", "centre_m": [50.0, 0.0, 10.0], "radius_m": 10.0, "max_speed_m_s": 12.0,
                        "max_accel_m_s2": 3.0}):
        m["bird"] = [{"id": "b", "count": 7, "wingspan_m": 1.0, "glide_fraction": 0.5, "trajectory": trajectory}]
        flocks.append(sky.FlockPoses(scene_from_mapping(copy.deepcopy(m)).others))
    return flocks


@pytest.mark.parametrize("n", [1, 2, 415, 3000])
def test_flock_pose_kernels_match_their_numpy_twins_to_the_bit(n):
    rng = np.random.default_rng(n)
    for flock in _flocks():
        m = np.sort(rng.integers(0, len(flock.objects), n))
        t = rng.uniform(-0.5, 20.5, n)
        assert np.array_equal(flock.positions(m, t), flock_positions_twin(flock, m, t))
        assert np.array_equal(flock.velocities(m, t), flock_velocities_twin(flock, m, t))
        p, v = flock.positions_velocities(m, t)
        assert np.array_equal(p, flock_positions_twin(flock, m, t))
        assert np.array_equal(v, flock_velocities_twin(flock, m, t))
        assert np.array_equal(flock.wing_angles(m, t), flock_wing_angles_twin(flock, m, t))



def _birds_motion(rng, n_birds, cone_lo, reach, radius_hi):
    """Random birds (or drones) for bodies_candidates_kernel and the twins: velocities, cone half-widths (``cone_lo``
    to 1.5 times ``reach``), body radii, accelerations (-1: none) and top speeds."""
    vel = rng.normal(size=(n_birds, 3)) * 8.0
    cone = rng.uniform(cone_lo, 1.5, n_birds) * reach
    radius = cone * rng.uniform(0.3, radius_hi, n_birds)
    accel = np.where(rng.random(n_birds) < 0.3, -1.0, rng.uniform(0.0, 20.0, n_birds))
    return vel, cone, radius, accel, np.linalg.norm(vel, axis=1) + 1.0

def _flock_cull(d, status, t_ray, t_mid, centres, vel, reach, radius, accel, v_max):
    """The sensor's cull of a flock: bodies_candidates_kernel on the rays' direction bounds, as
    ``(idx, member)``."""
    idx, start = K.bodies_candidates_kernel(d, status, t_ray, t_mid, centres, vel, reach, radius, accel, v_max, True,
                                            *_blocks(d, status))
    return idx, np.repeat(np.arange(centres.shape[0]), np.diff(start))


def test_a_flock_s_cull_is_its_twin_s_and_the_kernels_it_stands_for():
    rng = np.random.default_rng(12)
    d = rng.normal(size=(4000, 3)) + np.array([3.0, 0.0, 0.0])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    status = (rng.random(d.shape[0]) < 0.05).astype(np.uint8)
    t_ray = np.sort(rng.uniform(2.0, 2.1, d.shape[0]))
    # wide cones overlap: many (ray, bird) pairs
    for n_birds, spread, reach, pairs in ((20, 8.0, 0.4, 20), (6, 3.0, 6.0, 500), (2, 1.0, 1.0, 10)):
        centres = np.array([30.0, 0.0, 0.0]) + rng.normal(size=(n_birds, 3)) * spread
        vel, cone, radius, accel, v_max = _birds_motion(rng, n_birds, 0.5, reach, 0.9)
        args = (d, status, t_ray, 2.05, centres, vel, cone, radius, accel, v_max)
        idx, member = _flock_cull(*args)
        twin_idx, twin_member = flock_candidates_twin(*args)
        assert idx.size > pairs and np.array_equal(idx, twin_idx) and np.array_equal(member, twin_member)
        for k in range(n_birds):
            one = np.empty(d.shape[0], np.int64)
            one = one[:K.cone_candidates_kernel(d, status, *centres[k], cone[k], one)]
            kept = np.empty(one.size, np.int64)
            kept = kept[:K.moving_cull_kernel(one, d, t_ray, 2.05, centres[k], vel[k], radius[k], accel[k], v_max[k],
                                              kept)]
            assert np.array_equal(idx[member == k], kept)
    assert _flock_cull(d, status, t_ray, 2.05, centres + 1e3, vel, cone, radius, accel, v_max)[0].size == 0


def test_a_flock_cast_in_one_call_is_its_birds_cast_one_by_one():
    rng = np.random.default_rng(13)
    birds = [sky.bird_body(b) for b in (0.5, 0.6, 0.9)]
    prims = np.concatenate([b.body.prims for b in birds])
    hinge = np.concatenate([b.hinge for b in birds])
    prim_start = np.cumsum([0] + [b.body.prims.shape[0] for b in birds])
    centres = np.array([[9.0, 0.0, 0.0], [9.2, 0.3, 0.0], [8.0, -0.2, 0.1]])
    n = 6000
    d = centres[rng.integers(0, 3, n)] + rng.normal(0, 0.3, (n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    member = np.repeat(np.arange(3), [2500, 2000, 3000])        # overlapping: a ray may meet two birds
    idx = np.concatenate([rng.choice(n, 2500, replace=False), rng.choice(n, 2000, replace=False),
                          rng.choice(n, 3000, replace=False)])
    pos = centres[member] + rng.normal(0, 0.05, (member.size, 3))
    yaw = rng.uniform(-np.pi, np.pi, member.size)
    flap = rng.uniform(-0.6, 1.2, member.size)
    r, p = np.full(n, np.inf), np.full(n, -1, dtype=np.int64)
    r[::7] = 8.6                                             # something nearer on some rays already
    p[::7] = 99
    r1, p1, r2, p2 = r.copy(), p.copy(), r.copy(), p.copy()
    K.cast_flock_kernel(idx, member, d, pos, yaw, flap, prims, hinge, prim_start, 5, r1, p1)
    for k, b in enumerate(birds):
        rows = member == k
        K.cast_flapping_kernel(idx[rows], d, pos[rows], yaw[rows], flap[rows], b.body.prims, b.hinge,
                               5 + prim_start[k], r2, p2)
    assert np.array_equal(r1, r2) and np.array_equal(p1, p2)
    assert set(p1[p1 != 99]) >= set(range(5, 5 + prims.shape[0])) | {-1}
    rt, pt = cast_flock_twin(d, idx, member, pos, yaw, flap, prims, hinge, prim_start, 5, r, p)
    assert np.array_equal(p1, pt)
    f = np.isfinite(r1)
    np.testing.assert_allclose(r1[f], rt[f], rtol=1e-12)


def test_the_per_ray_cull_keeps_what_its_twin_keeps():
    # random rays, bodies and instants, with an acceleration bound and without; a few bodies right on
    # rays so that some candidates are kept and some dropped
    rng = np.random.default_rng(11)
    d = rng.normal(size=(5000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t_ray = np.sort(rng.uniform(2.0, 2.1, d.shape[0]))
    for trial in range(40):
        j = int(rng.integers(0, d.shape[0]))
        c = d[j] * rng.uniform(5.0, 80.0) + rng.normal(size=3) * 0.3
        v = rng.normal(size=3) * rng.uniform(0.0, 20.0)
        radius, v_max = rng.uniform(0.1, 0.6), float(np.linalg.norm(v)) + rng.uniform(0.0, 2.0)
        accel = -1.0 if trial % 3 == 0 else rng.uniform(0.0, 30.0)
        idx = np.empty(d.shape[0], np.int64)
        idx = idx[:K.cone_candidates_kernel(d, np.zeros(d.shape[0], np.uint8), *c, radius + v_max * 0.05 + 0.01, idx)]
        out = np.empty(idx.size, np.int64)
        kept = out[:K.moving_cull_kernel(idx, d, t_ray, 2.05, c, v, radius, accel, v_max, out)]
        assert np.array_equal(kept, moving_cull_twin(idx, d, t_ray, 2.05, c, v, radius, accel, v_max))
        assert set(kept.tolist()) <= set(idx.tolist())


def _assert_same_run(loop_a, log_a, loop_b, log_b):
    """Two closed-loop runs gave the same run: every log array (NaN where NaN) and every frame's truth
    of the objects."""
    for k in log_a:
        x, y = np.asarray(log_a[k]), np.asarray(log_b[k])
        assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), k
    assert loop_a.objects_log == loop_b.objects_log


def test_the_per_ray_cull_drops_only_rays_that_miss(monkeypatch):
    # The same runs with the per-ray cull passing every cone candidate through: every frame's points,
    # the truth (rays that hit each object) and the log are the same, and the cull cast far fewer
    # rays where things fly fast (the flock's birds at 8 m/s: a cone over the frame reaches ~0.8 m
    # from a bird's centre, its instant ~0.4 m; the crossing's drones at 1.2-1.4 m/s gain less).
    bodies_candidates = K.bodies_candidates_kernel

    def run(scene, keep_all):
        if keep_all:
            def everything(d, status, t_ray, t_mid, centres, vel, reach, radius, accel, v_max, instant, *blocks):
                return bodies_candidates(d, status, t_ray, t_mid, centres, vel, reach, radius, accel, v_max, False,
                                         *blocks)

            monkeypatch.setattr(K, "bodies_candidates_kernel", everything)     # the drones' and the birds'
        points = []
        loop = ClosedLoop(scene, frame_hook=lambda frame, out, lp: points.append(frame.xyz.tobytes()))
        log = loop.run()
        monkeypatch.undo()
        return loop, log, points

    for name, share in (("drone-and-flock", 0.4), ("two-drones-crossing", 0.9)):
        scene = replace(load_scene(SCENES / f"{name}.toml"), duration_s=3.0)
        (culled, log_c, pts_c), (full, log_f, pts_f) = run(scene, False), run(scene, True)
        assert pts_c == pts_f
        _assert_same_run(culled, log_c, full, log_f)
        assert sum(o.rays_hit for fr in culled.objects_log for o in fr) > 50
        print(name, culled.sensor.rays_cast_targets, full.sensor.rays_cast_targets)
        assert culled.sensor.rays_cast_targets < share * full.sensor.rays_cast_targets


def test_a_flock_cast_together_gives_the_run_it_gives_bird_by_bird():
    scene = replace(load_scene(SCENES / "drone-and-flock.toml"), duration_s=2.5)
    together = ClosedLoop(scene)
    apart = ClosedLoop(scene)
    apart.sensor._flocks = {}
    assert together.sensor._flocks
    a, b = together.run(), apart.run()
    _assert_same_run(together, a, apart, b)
    assert together.sensor.rays_cast_targets == apart.sensor.rays_cast_targets
    assert sum(o.rays_hit for fr in together.objects_log for o in fr if o.cls == "bird") > 50


# ---------------------------------------------------------------------------------------- trees

def test_crown_sways_at_its_stated_frequency_and_amplitude():
    rng = np.random.default_rng(11)
    path = sky.crown_sway(rng, (30.0, 0.0, 6.0), 0.3, 0.1, 0.25, 90.0, 2000.0)
    t = np.arange(0.0, 2000.0, 0.1)
    p = path.position(t)
    y = p[:, 1] - 0.0          # along the wind (toward +y)
    x = p[:, 0] - 30.0         # across it
    assert abs(np.sqrt(np.mean(y ** 2)) - 0.25) < 0.25 * 0.25
    assert abs(np.sqrt(np.mean(x ** 2)) - 0.125) < 0.125 * 0.25
    power = np.abs(np.fft.rfft(y - y.mean())) ** 2
    freq = np.fft.rfftfreq(y.size, 0.1)
    smooth = np.convolve(power, np.ones(200) / 200, mode="same")
    assert abs(freq[np.argmax(smooth)] - 0.3) < 0.03
    np.testing.assert_array_equal(p[:, 2], 6.0)


def test_tree_line_scene_has_trunks_in_the_background_and_crowns_that_move():
    scene = load_scene(SCENES / "drone-tree-line.toml")
    crowns = [o for o in scene.others if o.cls == "tree"]
    assert len(crowns) == 5
    plain = scene_from_mapping({k: v for k, v in _mapping("drone-tree-line").items() if k != "tree"})
    assert scene.background_prims.shape[0] == plain.background_prims.shape[0] + 5
    for c in crowns:
        p = c.trajectory.position(np.linspace(0, 20, 101))
        assert 0.05 < np.ptp(p[:, 1]) < 3.0


# ---------------------------------------------------------------------------------------- streams

def _positions(obj, t):
    return obj.trajectory.position(t)


def test_adding_birds_changes_no_drones_path_and_no_other_flocks_draws():
    base = _mapping("swarm-of-five")
    with_birds = copy.deepcopy(base)
    flock_a = {"id": "a", "count": 5, "wingspan_m": 0.4,
               "trajectory": {"type": "straight", "start_m": [40.0, 10.0, 8.0], "velocity_m_s": [0.0, -7.0, 0.0]}}
    flock_b = {"id": "b", "count": 7, "wingspan_m": 1.0,
               "trajectory": {"type": "manual", "centre_m": [50.0, 0.0, 10.0], "radius_m": 10.0,
                              "max_speed_m_s": 12.0, "max_accel_m_s2": 3.0}}
    with_birds["bird"] = [flock_a]
    both = copy.deepcopy(base)
    both["bird"] = [flock_b, flock_a]
    s0, s1, s2 = (scene_from_mapping(m) for m in (base, with_birds, both))
    t = np.linspace(0.0, 15.0, 301)
    for a, b, c in zip(s0.targets, s1.targets, s2.targets):   # drone-5 flies a seeded "manual" path
        np.testing.assert_array_equal(_positions(a, t), _positions(b, t))
        np.testing.assert_array_equal(_positions(a, t), _positions(c, t))
    a1 = [o for o in s1.others if o.id.startswith("a/")]
    a2 = [o for o in s2.others if o.id.startswith("a/")]
    assert len(a1) == len(a2) == 5
    for x, y in zip(a1, a2):
        np.testing.assert_array_equal(_positions(x, t), _positions(y, t))
        np.testing.assert_array_equal(x.flap.angle_rad(t), y.flap.angle_rad(t))


def test_stray_returns_draw_only_when_listed_and_from_their_own_stream():
    m = _mapping("swarm-of-five")
    plain = replace(scene_from_mapping(m), duration_s=1.0)
    loop = ClosedLoop(plain)
    loop.run()
    assert loop.draw_calls["stray_returns"] == 0
    m2 = copy.deepcopy(m)
    m2["scene"]["effects"] = m["scene"]["effects"] + ["stray_returns"]
    m2["effects"] = {"stray_rate_hz": 40.0, "stray_min_range_m": 2.0, "stray_max_range_m": 6.0}
    strays = replace(scene_from_mapping(m2), duration_s=5.0)
    loop = ClosedLoop(strays)
    loop.run()
    assert loop.draw_calls["stray_returns"] == 50
    clutter = [o for frame in loop.objects_log for o in frame if o.cls == "clutter"]
    assert 120 < len(clutter) <= 260, len(clutter)            # Poisson(200), less those lost
    r = np.array([np.linalg.norm(o.xyz_m) for o in clutter])
    assert r.min() >= 2.0 and r.max() <= 6.0
    assert len({o.id for o in clutter}) == len(clutter)


# ---------------------------------------------------------------------------------------- scenes

@pytest.mark.parametrize("table, key, value, says", [
    ("bird", "wingspan_m", 2.0, "wingspan_m"),
    ("bird", "count", 0, "count"),
    ("bird", "glide_fraction", 1.5, "glide_fraction"),
    ("bird", "colour", "red", "colour"),
    ("bird", "trajectory", {"type": "straight", "start_m": [30, 0, 5], "velocity_m_s": [0, 2, 0]}, "5-20 m/s"),
    ("bird", "trajectory", {"type": "straight", "start_m": [30, 0, 5], "velocity_m_s": [0, 25, 0]}, "20 m/s"),
    ("bird", "id", "two words", "id"),
    ("tree", "base_m", None, "base_m"),
    ("tree", "crown_radius_m", 9.0, "crown_radius_m"),
    ("tree", "sway_frequency_hz", 0.0, "sway_frequency_hz"),
    ("tree", "id", "drone", "id 'drone' is used twice"),
    ("target", "class", "bird", "class"),
])
def test_scene_errors_are_one_line_and_name_the_field(table, key, value, says):
    m = _mapping("drone-and-flock")
    m["tree"] = [{"id": "t", "base_m": [40.0, 20.0, -1.5]}]
    t = m[table][0]
    if value is None:
        del t[key]
    else:
        t[key] = value
    with pytest.raises(UserError) as exc:
        scene_from_mapping(m, "s.toml")
    msg = str(exc.value)
    assert "\n" not in msg and says in msg and "s.toml" in msg, msg


def test_stray_range_errors_name_the_field():
    m = _mapping("drone-tree-line")
    m["effects"] = {"stray_min_range_m": 9.0, "stray_max_range_m": 4.0}
    with pytest.raises(UserError, match=r"stray_min_range_m = 9.0 must be below stray_max_range_m"):
        scene_from_mapping(m, "s.toml")
    m = _mapping("two-drones-crossing")
    m["effects"] = {"stray_rate_hz": 5.0}
    with pytest.raises(UserError, match="stray_rate_hz belongs to effect 'stray_returns'"):
        scene_from_mapping(m, "s.toml")


@pytest.mark.parametrize("name", NEW_SCENES)
def test_new_scenes_record_the_truth_of_every_object(name, tmp_path):
    from foveatrack.cli import main
    from foveatrack.recording import RecordingReader

    out = tmp_path / name
    # 3 s: the scenes run the multi-object tracker, whose head holds still through the background's 1 s
    # warm-up; the tree line's drone, on the field's sparse rim, is hit only after that
    assert main(["simulate", str(SCENES / f"{name}.toml"), "--duration", "3", "--out", str(out), "--no-progress",
                 "--one-thread"]) == 0
    scene = load_scene(SCENES / f"{name}.toml")
    recs = RecordingReader(out / "run.mcap").records("truth_objects")
    ids = {r["id"]: r["class"] for r in recs if r["class"] != "clutter"}
    want = {s.id: s.cls for s in scene.targets} | {o.id: o.cls for o in scene.others}
    assert ids == want
    frames = {r["frame_id"] for r in recs}
    assert len(frames) == 30
    per_frame = [r for r in recs if r["frame_id"] == 5 and r["class"] != "clutter"]
    assert len(per_frame) == len(want)
    for r in per_frame:
        assert len(r["xyz_m"]) == 3 and len(r["velocity_m_s"]) == 3 and r["size_m"] > 0
    if name == "two-drones-crossing":
        a = next(r for r in per_frame if r["id"] == "drone-a")
        np.testing.assert_allclose(a["xyz_m"], [25.0, 6.0 - 1.2 * 0.55, 2.0], atol=1e-9)
        np.testing.assert_allclose(a["velocity_m_s"], [0.0, -1.2, 0.0], atol=1e-12)
    assert sum(r["rays_hit"] for r in recs if r["class"] == "drone") > 0


def test_single_target_scenes_write_no_object_truth(tmp_path):
    from foveatrack.recording import RecordingReader
    from foveatrack.cli import main

    assert not load_scene(SCENES / "fig12-tracking.toml").multi_object
    out = tmp_path / "fig12"
    assert main(["simulate", str(SCENES / "fig12-tracking.toml"), "--duration", "0.5", "--out", str(out),
                 "--no-progress", "--one-thread"]) == 0
    assert "truth_objects" not in RecordingReader(out / "run.mcap").channels()


def test_a_flock_s_cull_on_direction_bounds_is_the_twin_s_everywhere():
    """A flock's cull skips the blocks of rays its birds' cones cannot meet (kernels.ray_blocks_kernel):
    over flocks flattened and round, near and far, in every direction, a bird near the lidar (not
    bounded), and rays of a length off 1 (their blocks tested ray by ray), the same rays as each
    bird's own cull (bodies_candidates_twin) and, for rays of length 1 (the scan's, to the rounding),
    as the flock's cull before the blocks (the flock's cone, then each bird's: flock_candidates_twin;
    for rays a percent off length 1 that cone could drop a ray a bird's own test keeps)."""
    rng = np.random.default_rng(23)
    n_rays = 3000
    for trial in range(120):
        axis = rng.normal(size=3)
        if trial % 4 == 0:
            axis = np.eye(3)[trial // 4 % 3] * rng.choice([-1.0, 1.0])
        axis /= np.linalg.norm(axis)
        dist = rng.uniform(3.0, 120.0)
        n_birds = int(rng.integers(1, 30))
        flat = np.array([1.0, 1.0, rng.choice([1.0, 1.0 / 3.0])]) * rng.uniform(0.5, 12.0)
        centres = axis * dist + rng.normal(size=(n_birds, 3)) * flat
        if trial % 10 == 3:
            centres[0] = axis * rng.uniform(0.2, 1.5)             # a bird at the lidar: no box
        # rays about the flock's direction, some of them not of length 1
        d = axis + rng.normal(size=(n_rays, 3)) * rng.uniform(0.05, 0.6)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        if trial % 3 == 0:
            d[::7] *= 1.0 + rng.choice([-1.0, 1.0], d[::7].shape[0])[:, None] * rng.uniform(1e-7, 1e-2)
        status = (rng.random(n_rays) < 0.05).astype(np.uint8)
        t_ray = np.sort(rng.uniform(2.0, 2.1, n_rays))
        args = (d, status, t_ray, 2.05, centres) + _birds_motion(rng, n_birds, 0.3, 1.0, 1.0)
        idx, member = _flock_cull(*args)
        own_idx, own_start = bodies_candidates_twin(*args, True)
        assert np.array_equal(idx, own_idx), trial
        assert np.array_equal(member, np.repeat(np.arange(n_birds), np.diff(own_start))), trial
        if trial % 3:
            twin_idx, twin_member = flock_candidates_twin(*args)
            assert np.array_equal(idx, twin_idx) and np.array_equal(member, twin_member), trial


def _blocks(d, status):
    nb = -(-d.shape[0] // K.CULL_BLOCK)
    axis, cos, sin = np.empty((nb, 3)), np.empty(nb), np.empty(nb)
    K.ray_blocks_kernel(d, status, axis, cos, sin)
    return axis, cos, sin


def _scan_like_rays(rng, n, axis, spread):
    """Rays along a smooth random curve about ``axis`` (consecutive rays close, as a rosette scan's)."""
    phase = np.cumsum(rng.uniform(0.0, 0.02, n))
    e1 = np.cross(axis, [0.3, 0.5, 0.8])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    d = axis + spread * (np.sin(3.1 * phase)[:, None] * e1 + np.sin(5.3 * phase + 1.0)[:, None] * e2)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def test_ray_blocks_kernel_matches_its_twin_and_bounds_every_valid_ray():
    rng = np.random.default_rng(31)
    for trial in range(30):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        n = int(rng.integers(1, 3000))
        d = _scan_like_rays(rng, n, axis, rng.uniform(0.01, 2.0))
        if trial % 3 == 0:          # some rays off length 1, some failed in the prisms (zeros)
            d[::11] *= 1.0 + rng.uniform(-1e-3, 1e-3, d[::11].shape[0])[:, None]
        status = (rng.random(n) < 0.05).astype(np.uint8)
        if trial % 5 == 0:
            status[:K.CULL_BLOCK] = 1
            d[status != 0] = 0.0
        axis_k, cos_k, sin_k = _blocks(d, status)
        axis_t, cos_t, sin_t = ray_blocks_twin(d, status, K.CULL_BLOCK)
        assert np.array_equal(cos_k, cos_t) and np.array_equal(sin_k, sin_t), trial
        assert np.array_equal(axis_k[cos_k > -2.0], axis_t[cos_t > -2.0]), trial
        for b in np.flatnonzero((cos_k > -2.0) & (cos_k < 2.0)):
            rows = slice(b * K.CULL_BLOCK, (b + 1) * K.CULL_BLOCK)
            v = d[rows][status[rows] == 0]
            ang = np.arccos(np.clip(v @ axis_k[b] / np.linalg.norm(v, axis=1), -1, 1))
            assert np.all(ang <= np.arccos(cos_k[b])), (trial, b)


def test_bodies_candidates_kernel_is_each_body_s_cull_everywhere():
    """The bodies' culls in one call with the blocks' direction bounds: the rays of each body's own
    cone_candidates_kernel and moving_cull_kernel (and the twin's), over bodies near and far, behind
    the lidar and at it, cones narrow and wide, rays along a scan's curve and scattered, some off
    length 1 and some failed."""
    rng = np.random.default_rng(29)
    for trial in range(150):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        n = int(rng.integers(1, 4000))
        if trial % 4 == 3:
            d = rng.normal(size=(n, 3)) + axis * 2.0
            d /= np.linalg.norm(d, axis=1, keepdims=True)
        else:
            d = _scan_like_rays(rng, n, axis, rng.uniform(0.05, 0.8))
        if trial % 3 == 0:
            d[::7] *= 1.0 + rng.choice([-1.0, 1.0], d[::7].shape[0])[:, None] * rng.uniform(1e-8, 1e-4)
        status = (rng.random(n) < 0.05).astype(np.uint8)
        t_ray = np.sort(rng.uniform(2.0, 2.1, n))
        n_bodies = int(rng.integers(0, 8))
        # bodies on rays (some candidates), anywhere about the axis, one at the lidar, one behind it
        centres = d[rng.integers(0, n, n_bodies)] * rng.uniform(2.0, 150.0, (n_bodies, 1))
        centres += rng.normal(size=(n_bodies, 3)) * rng.uniform(0.0, 2.0)
        if n_bodies > 2 and trial % 5 == 0:
            centres[1] = rng.normal(size=3) * 0.3
            centres[2] = -axis * 20.0
        vel, cone, radius, accel, v_max = _birds_motion(rng, n_bodies, 0.3, rng.uniform(0.1, 3.0), 1.0)
        if n_bodies and trial % 7 == 0:
            cone[0] = np.inf
        for instant in (True, False):
            args = (d, status, t_ray, 2.05, centres.reshape(-1, 3), vel.reshape(-1, 3), cone, radius, accel, v_max,
                    instant)
            idx, start = K.bodies_candidates_kernel(*args, *_blocks(d, status))
            twin_idx, twin_start = bodies_candidates_twin(*args)
            assert np.array_equal(idx, twin_idx) and np.array_equal(start, twin_start), trial
            # the rays' times given in ns: each formed as t_ns * 1e-9, the same rays
            t_ns = np.sort(rng.integers(2_000_000_000, 2_100_000_000, n))
            args_ns = (d, status, t_ns) + args[3:]
            args_s = (d, status, t_ns * 1e-9) + args[3:]
            for a, b in zip(K.bodies_candidates_kernel(*args_ns, *_blocks(d, status)),
                            K.bodies_candidates_kernel(*args_s, *_blocks(d, status))):
                assert np.array_equal(a, b), trial
            for k in range(n_bodies):
                one = np.empty(n, np.int64)
                one = one[:K.cone_candidates_kernel(d, status, *centres[k], cone[k], one)]
                if instant:
                    kept = np.empty(one.size, np.int64)
                    one = kept[:K.moving_cull_kernel(one, d, t_ray, 2.05, centres[k], vel[k], radius[k], accel[k],
                                                     v_max[k], kept)]
                assert np.array_equal(idx[start[k]:start[k + 1]], one), (trial, k)


def test_targets_on_straight_passes_cast_together_give_the_run_each_cast_on_its_own(monkeypatch):
    import sim.sensor as sensor_module

    scene = replace(load_scene(SCENES / "swarm-of-five.toml"), duration_s=2.5)
    together = ClosedLoop(scene)
    a = together.run()
    assert any(together.sensor._straight.cast_together)
    of = sensor_module._StraightBodies.of

    def apart(bodies, n_targets, has):
        s = of(bodies, n_targets, has)
        return s._replace(any=False, is_straight=[False] * len(s.is_straight),
                          cast_together=[False] * len(s.cast_together), run_at={})
    monkeypatch.setattr(sensor_module._StraightBodies, "of", apart)
    alone = ClosedLoop(scene)
    b = alone.run()
    assert not any(alone.sensor._straight.cast_together)
    _assert_same_run(together, a, alone, b)
    assert together.sensor.rays_cast_targets == alone.sensor.rays_cast_targets
    assert sum(o.rays_hit for fr in together.objects_log for o in fr if o.cls == "drone") > 50
