import math

import numpy as np
import pytest

from fakes import FakeHead
from foveatrack.control import HeadCommand
from foveatrack.detection import Detection, wrap_deg
from foveatrack.reconstruction import Reconstructor, rotation_matrix, rotation_rows
from foveatrack.speed_table import AxisTable, SpeedEntry, SpeedTable


def test_rotation_convention_hand_cases():
    assert np.allclose(rotation_matrix(0, 0), np.eye(3))
    assert np.allclose(rotation_matrix(90, 0) @ [1, 0, 0], [0, 1, 0])       # pan left 90: X -> +Y
    assert np.allclose(rotation_matrix(0, 90) @ [1, 0, 0], [0, 0, 1])       # tilt up 90: X -> +Z
    p, t = math.radians(30), math.radians(20)
    assert np.allclose(rotation_matrix(30, 20) @ [1, 0, 0],
                       [math.cos(t) * math.cos(p), math.cos(t) * math.sin(p), math.sin(t)])
    assert np.allclose(rotation_matrix(30, 20) @ [0, 1, 0], [-math.sin(p), math.cos(p), 0])  # tilt axis horizontal


def test_integration_matches_fake_head_with_dead_time_and_accel():
    table = SpeedTable.nominal()
    sp = lambda b: table.pan.speed_deg_s(b)   # noqa: E731
    st = lambda b: table.tilt.speed_deg_s(b)  # noqa: E731
    head = FakeHead(sp, st, dead_time_s=0.05, accel_deg_s2=40.0, pan0=170.0, tilt0=5.0)
    rec = Reconstructor(table, pan0_deg=170.0, tilt0_deg=5.0, latency_s=0.01, dead_time_s=0.05,
                        accel_deg_s2=40.0)
    rng = np.random.default_rng(3)
    t = 0.0
    for _ in range(200):
        cmd = HeadCommand(int(rng.integers(-1, 2)), 0, int(rng.integers(-1, 2)), 0)
        cmd = HeadCommand(cmd.pan_dir, int(rng.integers(0, 64)) if cmd.pan_dir else 0,
                          cmd.tilt_dir, int(rng.integers(0, 64)) if cmd.tilt_dir else 0)
        rec.on_command(t, cmd)
        head.command(t + 0.01, cmd)      # arrives after the link latency
        t += float(rng.uniform(0.05, 0.5))
        head.advance(t)
        p, ti, spn, stn = rec.angles_at(t)
        assert wrap_deg(p - head.ang["pan"]) == pytest.approx(0.0, abs=1e-9)
        assert ti == pytest.approx(min(max(head.ang["tilt"], -90), 90), abs=1e-9)
        assert spn > 0 or t < 0.1


def test_uncertainty_bounds_drift_over_hours_and_rotation_stays_orthonormal():
    # true head speeds differ from the table by per-byte errors drawn from the table's sigma
    rng = np.random.default_rng(7)
    rel = 0.01
    table = SpeedTable(
        AxisTable("pan", tuple(SpeedEntry(b, 0.2 * (b + 1), rel * 0.2 * (b + 1)) for b in range(64))),
        AxisTable("tilt", tuple(SpeedEntry(b, 0.05 * (b + 1), rel * 0.05 * (b + 1)) for b in range(64))))
    errs_p = rng.normal(0, rel, 64)
    errs_t = rng.normal(0, rel, 64)
    head = FakeHead(lambda b: table.pan.speed_deg_s(b) * (1 + errs_p[b]),
                    lambda b: table.tilt.speed_deg_s(b) * (1 + errs_t[b]))
    rec = Reconstructor(table, timing_sigma_s=0.0)
    t, hours = 0.0, 3.0
    # a biased random command sequence: the pan keeps turning (wraps many times)
    zs = []
    while t < hours * 3600:
        b = int(rng.integers(0, 64))
        pd = 1 if rng.random() < 0.7 else -1
        td = int(rng.choice([-1, 1]))
        cmd = HeadCommand(pd, b, td, int(rng.integers(0, 64)))
        rec.on_command(t, cmd)
        head.command(t, cmd)
        t += 2.0
        head.advance(t)
        p, ti, s_p, s_t = rec.angles_at(t)
        zs.append((wrap_deg(p - head.ang["pan"]) / s_p, (ti - head.ang["tilt"]) / s_t))
        R = rotation_matrix(p, ti)
        assert np.allclose(R.T @ R, np.eye(3), atol=1e-12) and abs(np.linalg.det(R) - 1) < 1e-12
    zs = np.array(zs)
    assert head.ang["pan"] > 10 * 360          # it really turned round many times
    assert np.abs(zs).max() < 4.0               # drift bounded by the stated uncertainty


def test_stated_uncertainty_is_calibrated_across_units():
    # many units (independent per-byte speed errors), same commands: final error / sigma ~ N(0, 1)
    rel = 0.02
    table = SpeedTable(
        AxisTable("pan", tuple(SpeedEntry(b, 0.2 * (b + 1), rel * 0.2 * (b + 1)) for b in range(64))),
        AxisTable("tilt", tuple(SpeedEntry(b, 0.05 * (b + 1), rel * 0.05 * (b + 1)) for b in range(64))))
    rng = np.random.default_rng(11)
    cmds = [HeadCommand(int(rng.choice([-1, 1])), int(rng.integers(0, 64)), 0, 0) for _ in range(200)]
    z = []
    for unit in range(40):
        e = rng.normal(0, rel, 64)
        head = FakeHead(lambda b: table.pan.speed_deg_s(b) * (1 + e[b]), table.tilt.speed_deg_s)
        rec = Reconstructor(table, timing_sigma_s=0.0)
        for i, c in enumerate(cmds):
            rec.on_command(i * 1.0, c)
            head.command(i * 1.0, c)
        head.advance(len(cmds) * 1.0)
        p, _, s_p, _ = rec.angles_at(len(cmds) * 1.0)
        z.append(wrap_deg(p - head.ang["pan"]) / s_p)
    assert 0.6 < np.std(z) < 1.5 and abs(np.mean(z)) < 0.6


def test_to_world_places_a_detection():
    table = SpeedTable.nominal()
    rec = Reconstructor(table, pan0_deg=90.0, tilt0_deg=0.0, sigma0_deg=0.1)
    det = Detection(0.0, np.array([10.0, 0.0, 0.0]), 5, 0.0, 0.0, 10.0)
    w, s = rec.to_world(det)
    assert np.allclose(w, [0, 10, 0])
    assert s == pytest.approx(math.hypot(10 * math.radians(0.1), 10 * math.radians(0.1)))


def _axis_states(rec, t):
    """The general route: each axis integrated afresh (no memo)."""
    p, _, sp = rec.pan.state(t)
    ti, _, st = rec.tilt.state(t)
    return p, ti, sp, st


def test_memoised_angles_equal_fresh_integration_across_commands():
    """angles_at keeps answers across a command only for instants before its effect time (and
    inside the retained history); every answer equals a fresh integration, bit for bit."""
    table = SpeedTable.nominal()
    rec = Reconstructor(table, pan0_deg=175.0, tilt0_deg=5.0, latency_s=0.01, dead_time_s=0.05,
                        accel_deg_s2=40.0, history_s=2.0)
    rng = np.random.default_rng(11)
    t = 0.0
    n_hits = 0
    for _ in range(300):
        d = rng.integers(-1, 2, 2)
        cmd = HeadCommand(int(d[0]), int(rng.integers(0, 64)) if d[0] else 0,
                          int(d[1]), int(rng.integers(0, 64)) if d[1] else 0)
        t_eff = t + rec.effect_delay_s
        # instants before, at and after this command's effect; some asked before it is sent
        asked = [t - 0.05, t_eff - 1e-9, t_eff, t_eff + 0.02, t - 2.5]
        rec._memo.clear()   # (the memo holds at most 8 instants; start this round with room)
        rec._n_carried = 0
        for q in asked[:3]:
            rec.angles_at(q)
        rec.on_command(t, cmd)
        assert t_eff not in rec._memo
        n_hits += sum(q in rec._memo for q in asked[:2])
        for q in asked + [t + float(rng.uniform(0, 0.3))]:
            assert rec.tilt_at(q) == _axis_states(rec, q)[1::2]
            assert rec.angles_at(q) == _axis_states(rec, q)
            assert rec.angles_at(q) == _axis_states(rec, q)   # a second ask (a memo hit)
            assert rec.tilt_at(q) == _axis_states(rec, q)[1::2]
        t += float(rng.uniform(0.02, 0.3))
    assert n_hits > 500   # the memo did carry answers across commands


def test_a_second_command_at_the_same_instant_replaces_the_first():
    """A driver may register a command and then, at the same instant, the one actually sent (its
    safety gate limited it, its write failed, the head is frozen).  That is one change of speed: the
    angles *and* the timing uncertainty must be those of the second command alone."""
    table = SpeedTable.nominal()
    kw = dict(pan0_deg=10.0, tilt0_deg=5.0, latency_s=0.007, dead_time_s=0.04, accel_deg_s2=40.0)
    once, twice = Reconstructor(table, **kw), Reconstructor(table, **kw)
    rng = np.random.default_rng(8)
    t = 0.0
    for _ in range(60):
        pd, td = int(rng.integers(-1, 2)), int(rng.integers(-1, 2))
        cmd = HeadCommand(pd, int(rng.integers(1, 64)) if pd else 0, td, int(rng.integers(1, 64)) if td else 0)
        other = HeadCommand(1, 40, -1, 30)
        once.on_command(t, cmd)
        twice.on_command(t, other)          # replaced at the same instant ...
        twice.on_command(t, cmd)            # ... by what was sent
        t += float(rng.uniform(0.05, 0.3))
    for u in np.linspace(0.0, t + 1.0, 200):
        assert twice.angles_at(u) == once.angles_at(u)
    assert len(twice.pan.knots) == len(once.pan.knots)


def test_a_repeated_command_object_integrates_as_a_fresh_equal_one():
    """on_command skips both axes when the very command object it ran last comes again later (the
    tracker's commands are shared instances, :func:`foveatrack.control.head_command`): the knots and
    every answer equal those of a reconstruction fed equal but distinct commands (which take every
    test), also when a repeat comes at the same instant."""
    from foveatrack.control import head_command

    table = SpeedTable.nominal()
    kw = dict(pan0_deg=170.0, tilt0_deg=5.0, latency_s=0.007, dead_time_s=0.04, accel_deg_s2=40.0, history_s=3.0)
    shared, fresh = Reconstructor(table, **kw), Reconstructor(table, **kw)
    rng = np.random.default_rng(5)
    t, n_repeats = 0.0, 0
    key = (0, 0, 0, 0)
    for _ in range(400):
        if rng.random() < 0.4:   # a new command; otherwise the last one again
            pd, td = int(rng.integers(-1, 2)), int(rng.integers(-1, 2))
            key = (pd, int(rng.integers(1, 64)) if pd else 0, td, int(rng.integers(1, 64)) if td else 0)
        else:
            n_repeats += 1
        shared.on_command(t, head_command(*key))
        fresh.on_command(t, HeadCommand(*key))
        if rng.random() < 0.1:   # the same command again at the same instant
            shared.on_command(t, head_command(*key))
            fresh.on_command(t, HeadCommand(*key))
        for u in (t - 0.03, t + 0.01, t + 0.05):
            assert shared.angles_at(u) == fresh.angles_at(u)
        t += float(rng.uniform(0.05, 0.15))
    assert n_repeats > 150
    for a, b in ((shared.pan, fresh.pan), (shared.tilt, fresh.tilt)):
        assert a.times == b.times
        assert [(k.angle, k.v, k.v_tgt, k.idx, k.var_timing, k.var_bytes) for k in a.knots] == \
            [(k.angle, k.v, k.v_tgt, k.idx, k.var_timing, k.var_bytes) for k in b.knots]


def test_rotation_rows_are_rotation_matrixs_entries():
    rng = np.random.default_rng(5)
    for pan, tilt in zip(rng.uniform(-400, 400, 500), rng.uniform(-90, 90, 500)):
        assert np.array(rotation_rows(pan, tilt)).tobytes() == rotation_matrix(pan, tilt).tobytes()


def test_to_world_turns_as_lidar_to_world_and_the_box_kernel_do():
    """to_world turns the point in the fixed order of :mod:`foveatrack.fixed_order` (not BLAS's, which
    differs per CPU): the bits of ``lidar_to_world`` (the box kernel's turn), and ``R @ q`` within twice
    the rounding bound of a 3-term dot product, ``2 * 3u sum |r_k q_k|`` (checked over many poses)."""
    rng = np.random.default_rng(4)
    table = SpeedTable.nominal()
    for _ in range(2000):
        pan, tilt = float(rng.uniform(-180, 180)), float(rng.uniform(-89, 89))
        offset = rng.normal(0, 0.1, 3)
        rec = Reconstructor(table, pan0_deg=pan, tilt0_deg=tilt, lidar_offset_m=offset, sigma0_deg=0.1)
        xyz = rng.normal(0, 30, 3)
        w, sigma = rec.to_world(Detection(0.0, xyz, 5, 0.0, 0.0, 1.0))
        assert w.tobytes() == rec.lidar_to_world(xyz, 0.0)[0].tobytes()
        R, q = rotation_matrix(pan, tilt), xyz + offset
        bound = 6 * 2.0**-53 * (np.abs(R) @ np.abs(q)) * (1 + 1e-15)
        assert np.all(np.abs(w - R @ q) <= bound)
        assert math.isfinite(sigma) and sigma > 0


def test_pan_tilt_many_is_angles_at_bit_for_bit():
    """pan_tilt_many (a frame's node poses, without the sigmas) gives angles_at's two angles to the bit:
    commands with dead time and acceleration, the tilt's stops, pan wrapping round 180, instants before
    the start, inside and after the kept history (NaN), memo hits and misses; and it leaves the memo
    as it found it."""
    table = SpeedTable.nominal()
    for tilt0, limits in ((5.0, (-90.0, 90.0)), (80.0, (-10.0, 85.0))):
        rec = Reconstructor(table, pan0_deg=175.0, tilt0_deg=tilt0, t0_s=1.0, latency_s=0.01, dead_time_s=0.05,
                            accel_deg_s2=40.0, tilt_limits_deg=limits, history_s=2.0)
        fresh = Reconstructor(table, pan0_deg=175.0, tilt0_deg=tilt0, t0_s=1.0, latency_s=0.01, dead_time_s=0.05,
                              accel_deg_s2=40.0, tilt_limits_deg=limits, history_s=2.0)
        rng = np.random.default_rng(21)
        t = 1.0
        for step in range(250):
            d = rng.integers(-1, 2, 2)
            cmd = HeadCommand(int(d[0]), int(rng.integers(0, 64)) if d[0] else 0,
                              int(d[1]), int(rng.integers(0, 64)) if d[1] else 0)
            for r in (rec, fresh):
                r.on_command(t, cmd)
            ts = [t + 0.1 * i / 10 for i in range(11)] + [0.5, 1.0, t - 1.9, t - 3.0, t + 5.0]
            if step % 3 == 0:
                rec.angles_at(ts[4])          # one of them in the memo
            memo = dict(rec._memo)
            got = rec.pan_tilt_many(ts)
            assert rec._memo == memo
            want = [fresh.angles_at(q)[:2] for q in ts]
            assert np.array(got).tobytes() == np.array(want).tobytes()
            assert all(type(a) is float and type(b) is float for a, b in got)
            assert rec.pan_tilt_array(ts).tobytes() == np.array(want).tobytes()      # the kernel's
            assert rec.pan_tilt_array(ts[:11]).tobytes() == np.array(want[:11]).tobytes()
            assert rec._memo == memo
            t += float(rng.uniform(0.02, 0.3))


def test_a_reversal_short_of_its_stop_is_the_kernel_s_and_one_that_may_reach_it_the_twin_s():
    """axis_angles_kernel on a tilt knot reversing toward a stop: where the deceleration clearly stops
    short of the stop (most reversals), the kernel's angle, the same bits as _AxisIntegrator.angle's;
    where it may reach the stop (its test with ``m ** 2``), left to the twin (``py`` set)."""
    from foveatrack.kernels import axis_angles_kernel
    from foveatrack.reconstruction import _Knot

    rec = Reconstructor(SpeedTable.nominal(), pan0_deg=0.0, tilt0_deg=0.0, t0_s=0.0, latency_s=0.01,
                        dead_time_s=0.03, accel_deg_s2=40.0, tilt_limits_deg=(-30.0, 60.0), history_s=3.0)
    ax = rec.tilt
    rng = np.random.default_rng(11)
    kernel_s = twin_s = 0
    for _ in range(3000):
        lo, hi = ax.limits
        accel = float(rng.choice([20.0, 40.0, 300.0, rng.uniform(5.0, 500.0)]))
        v = float(rng.choice([-1.0, 1.0]) * rng.uniform(0.5, 120.0))
        vt = float(-math.copysign(rng.uniform(0.5, 120.0), v))
        # near a stop (often within the deceleration's reach), or anywhere
        ang0 = float(rng.choice([rng.uniform(lo, hi), hi - rng.uniform(0.0, 3.0), lo + rng.uniform(0.0, 3.0)]))
        ax.accel = accel
        ax.knots = [_Knot(1.0, ang0, v, vt, 5, 1, np.zeros(65), 0.0)]
        ax.times = [1.0]
        ts = 1.0 + np.sort(rng.uniform(0.0, 3.0 * abs(v) / accel + 0.1, 11))
        out = np.zeros((11, 1))
        py = np.zeros(11, np.bool_)
        n = axis_angles_kernel(np.array([[1.0, ang0, v, vt]]), accel, True, lo, hi, True, False, ts, out, 0, py)
        assert n == int(py.sum())
        for i, t in enumerate(ts.tolist()):
            if not py[i]:
                assert out[i, 0].tobytes() == np.float64(ax.angle(t)).tobytes()
        kernel_s += int((~py).sum())
        twin_s += n
    assert kernel_s > 10_000 and twin_s > 1_000, (kernel_s, twin_s)


@pytest.mark.parametrize("accel", [None, 40.0, 300.0])
def test_pan_tilt_array_is_angle_s_twin_on_every_branch(accel):
    """Reconstructor.pan_tilt_array (axis_angles_kernel) against _AxisIntegrator.angle, bit for bit:
    the speed at once (no acceleration) or ramped, inside and past the ramp, the tilt into its stops
    and reversing off them (the twin's path), pan wrapping round 180 both ways, the frame's eleven
    nodes spanning a command's effect."""
    table = SpeedTable.nominal()
    rec = Reconstructor(table, pan0_deg=-178.0, tilt0_deg=60.5, t0_s=0.0, latency_s=0.01, dead_time_s=0.03,
                        accel_deg_s2=accel or 40.0, tilt_limits_deg=(59.0, 62.0), history_s=3.0)
    if accel is None:
        rec.pan.accel = rec.tilt.accel = None
    rng = np.random.default_rng(5)
    t, branches = 0.0, set()
    for step in range(400):
        d = rng.integers(-1, 2, 2)
        rec.on_command(t, HeadCommand(int(d[0]), int(rng.integers(0, 64)) if d[0] else 0,
                                      int(d[1]), int(rng.integers(30, 64)) if d[1] else 0))
        ts = [t + 0.1 * i / 10 for i in range(11)]
        got = rec.pan_tilt_array(ts)
        want = [(rec.pan.angle(q), rec.tilt.angle(q)) for q in ts]
        assert got.tobytes() == np.array(want, np.float64).tobytes()
        assert rec.pan_tilt_array(ts, True).tobytes() == got.tobytes()     # (the nodes' times increase)
        branches |= {("wrap", a > 0) for a, _ in want if abs(a) > 175.0}
        branches |= {("stop", b) for _, b in want if b in (59.0, 62.0)}
        branches |= {"reversal" for k in rec.tilt.knots[-2:] if k.v * k.v_tgt < 0.0 and rec.tilt.accel}
        t += float(rng.uniform(0.02, 0.2))
    assert {("stop", 59.0), ("stop", 62.0), ("wrap", True), ("wrap", False)} | ({"reversal"} if accel else set()) <= branches, branches
