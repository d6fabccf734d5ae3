"""Work done ahead on a second thread (sim/ahead.py: the scan, the effects' draws) changes nothing but
the wall time."""

import math
import subprocess
import sys
import textwrap
import threading
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from sim.loop import ClosedLoop
from sim import effects as fx
from sim.ahead import Ahead, DrawsAhead, ScanAhead
from sim.scan.optics import SpeedNoise
from sim.scene import load_scene
from sim.sensor import scene_scan_model

ROOT = Path(__file__).resolve().parents[2]
SCENES = ROOT / "scenes"


def _run(scene, ahead):
    points = []
    loop = ClosedLoop(scene, frame_hook=lambda frame, out, loop_: points.append(
        (frame.xyz.copy(), frame.t_ns.copy(), frame.reflectivity.copy())))
    log = loop.run(ahead=ahead)
    return log, points, loop


ALL_ONE_KIND = frozenset({"range_noise", "angular_noise", "return_probability", "dropouts", "motor_speed_noise"})


@pytest.mark.determinism
@pytest.mark.parametrize("name, effects", [("fig12-tracking", None), ("noisy-link", None),
                                           ("fig12-tracking", ALL_ONE_KIND | {"sunlight"})])
def test_a_run_with_work_done_ahead_is_the_run_without_it_to_the_bit(name, effects):
    scene = replace(load_scene(SCENES / f"{name}.toml"), duration_s=2.5)   # 25 frames: three scan batches
    if effects is not None:
        from sim.scene import EFFECT_DEFAULTS

        params = {k: v for e in effects for k, v in EFFECT_DEFAULTS.get(e, {}).items()}
        scene = replace(scene, effects=effects, effect_params={**params, **scene.effect_params, "dropout_rate": 0.05,
                                                               "sunlight_rate": 1e-3})
    log_a, pts_a, loop_a = _run(scene, ahead=False)
    log_b, pts_b, loop_b = _run(scene, ahead=True)
    assert loop_b._scan_ahead is None            # the worker is gone when run() returns
    for k in log_a:
        assert np.array_equal(log_a[k], log_b[k], equal_nan=log_a[k].dtype.kind == "f"), k
    assert len(pts_a) == len(pts_b) == 25
    for a, b in zip(pts_a, pts_b):
        for x, y in zip(a, b):
            assert x.dtype == y.dtype and np.array_equal(x, y)
    assert loop_a.scan.noise_draws == loop_b.scan.noise_draws


def _model(drift_frac=0.0):
    scene = load_scene(SCENES / "fig12-tracking.toml")
    model = scene_scan_model(replace(scene, effects=scene.effects - {"motor_speed_noise"}))
    noise = SpeedNoise(sigma_frac=0.01, segment_s=0.01, drift_frac=drift_frac)
    return type(model)(scene.optics, "exact", speed_noise=noise, rng=np.random.default_rng(7))


@pytest.mark.parametrize("drift_frac", [0.0, 0.002])     # the fused kernel, and the composed path
def test_frames_in_any_order_equal_the_model_asked_directly(drift_frac):
    period = 0.1
    worker = Ahead()
    ahead = ScanAhead(_model(drift_frac), period, worker, batch_frames=3)
    ref = _model(drift_frac)
    # in order, a skip forward, a step back (the batch is dropped and traced again), off the frame grid
    asks = [(0.0, 0.1), (0.1, 0.2), (0.2, 0.3), (0.3, 0.4), (0.9, 1.0), (1.0, 1.1), (0.4, 0.5), (0.45, 0.55)]
    try:
        for t0, t1 in asks:
            a, b = ahead.scan_time(t0, t1), ref.scan_time(t0, t1)
            assert a.k0 == b.k0
            for f in ("t_ns", "direction", "channel", "status"):
                assert np.array_equal(getattr(a, f), getattr(b, f)), (t0, f)
    finally:
        worker.close()


@pytest.mark.parametrize("kw, message", [({"period_s": 0.0}, "period_s"), ({"period_s": 0.1, "batch_frames": 0},
                                                                             "batch_frames")])
def test_bad_arguments_are_named(kw, message):
    worker = Ahead()
    try:
        with pytest.raises(ValueError, match=message):
            ScanAhead(_model(), ahead=worker, **kw)
        with pytest.raises(ValueError, match="kind"):
            DrawsAhead(np.random.default_rng(0), "poisson", worker)
    finally:
        worker.close()


SIZES = [0, 1, 7, 5000, 3, 65_536, 12_345, 999, 70_000, 2]     # across block ends, and longer than a block


def test_numpy_draws_do_not_depend_on_how_a_run_of_them_is_split():
    # What drawing ahead relies on, checked against the installed numpy: a stream's values are the
    # same whether drawn in one call or many, and normal(0, s) is 0 + s * standard_normal.
    whole = np.random.default_rng(5)
    u = whole.random(sum(SIZES))
    parts = np.random.default_rng(5)
    assert np.array_equal(u, np.concatenate([parts.random(n) for n in SIZES]))
    z = np.random.default_rng(6).standard_normal(sum(SIZES))
    parts = np.random.default_rng(6)
    assert np.array_equal(0.0 + 0.02 * z, np.concatenate([parts.normal(0.0, 0.02, n) for n in SIZES]))


@pytest.mark.determinism     # CI runs these again with numba's generic target
@pytest.mark.parametrize("seed", [0, 5, 2**63 + 11])
def test_the_fill_kernels_draw_what_numpy_draws(seed):
    from sim import random_kernels as rk

    for kernel, twin in ((rk.fill_standard_normal_kernel, "standard_normal"), (rk.fill_uniform_kernel, "random")):
        ref, gen = np.random.default_rng(seed), np.random.default_rng(seed)
        for n in (0, 1, 200_000, 3):          # 200 k normals take the ziggurat's tail a few hundred times
            out = np.empty(n)
            kernel(gen, out)
            assert np.array_equal(out, getattr(ref, twin)(n)), (twin, n)
        assert gen.bit_generator.state == ref.bit_generator.state


@pytest.mark.parametrize("block", [1, 1000, 65_536])
def test_draws_ahead_equal_the_generators_own(block):
    worker = Ahead()
    try:
        u_ahead = DrawsAhead(np.random.default_rng(1), "uniform", worker, block=block)
        n_ahead = DrawsAhead(np.random.default_rng(2), "normal", worker, block=block)
        u_ref, n_ref = np.random.default_rng(1), np.random.default_rng(2)
        for n in SIZES[:6] if block == 1 else SIZES:
            assert np.array_equal(u_ahead.random(n), u_ref.random(n))
            sigma = 0.02 if n % 2 else 1.5e-4
            # through the effects' own draw functions, against numpy's normal() itself
            assert np.array_equal(fx.range_noise_draws(n_ahead, n, sigma), n_ref.normal(0.0, sigma, n))
            assert np.array_equal(fx.angular_noise_draws(n_ahead, n, 0.03),
                                  n_ref.normal(0.0, math.radians(0.03), (n, 3)))
            assert np.array_equal(fx.range_noise_draws(np.random.default_rng(n), n, sigma),
                                  np.random.default_rng(n).normal(0.0, sigma, n))
        with pytest.raises(TypeError, match="uniforms"):
            n_ahead.random(3)
    finally:
        worker.close()
    # after the worker is closed the stream goes on, drawing on the caller's thread
    assert np.array_equal(u_ahead.random(70_000), u_ref.random(70_000))


# A Ctrl-C lands in the loop's thread at any bytecode boundary (the signal handler runs between two
# instructions).  This child process raises KeyboardInterrupt at the n-th instruction the main thread
# executes in each of the worker's hand-offs, for every n until the hand-off ends by itself, and
# checks after each that the worker still ends (close() within 20 s, in a helper thread: the old
# concurrent.futures hand-off left a lock taken there and hung for ever, worker and exit alike).
INTERRUPTED = textwrap.dedent(
    """
    import os, sys, threading
    sys.path.insert(0, {root!r})
    from sim.ahead import Ahead

    def interrupt_at(n, then=None):
        count = [0]
        def tracer(frame, event, arg):
            frame.f_trace_opcodes = True
            if event == "opcode":
                count[0] += 1
                if count[0] == n:
                    sys.settrace(None)
                    if then is not None:
                        then()
                    raise KeyboardInterrupt(f"{{frame.f_code.co_filename}}:{{frame.f_lineno}}")
            return tracer
        return tracer

    def traced(fn, n, then=None):
        sys.settrace(interrupt_at(n, then))
        try:
            fn()
            return False
        except KeyboardInterrupt:
            return True
        finally:
            sys.settrace(None)

    def ends(ahead, what):
        closer = threading.Thread(target=ahead.close, daemon=True)
        closer.start()
        closer.join(20)
        left = [t.name for t in threading.enumerate() if t.name.startswith("sim-ahead") and t.is_alive()]
        if closer.is_alive() or left:
            print("HANG", what, left, flush=True)
            os._exit(3)

    cases = 0
    for case in ("wait", "wait_done", "submit", "close"):
        for n in range(1, 10_000):
            ahead = Ahead()
            if case == "wait":      # the worker finishes while (or just after) the loop's thread waits
                gate = threading.Event()
                job = ahead.submit(lambda: (gate.wait(), 7)[1])
                threading.Timer(0.2, gate.set).start()
                hit = traced(job.result, n, then=gate.set)
            elif case == "wait_done":   # the result is in before the wait starts
                job = ahead.submit(int, 7)
                job.result()
                hit = traced(job.result, n)
            elif case == "submit":
                hit = traced(lambda: ahead.submit(int, 7), n)
            else:
                ahead.submit(int, 7)
                hit = traced(ahead.close, n)
            ends(ahead, f"{{case}} n={{n}}")
            if not hit:         # n is past the hand-off's last instruction: every one was tried
                break
            cases += 1
    print("ok", cases, flush=True)
    """
)


@pytest.mark.slow
def test_a_ctrl_c_at_any_instruction_of_a_hand_off_leaves_the_worker_free():
    p = subprocess.run([sys.executable, "-c", INTERRUPTED.format(root=str(ROOT))], capture_output=True,
                       text=True, timeout=600)
    assert p.returncode == 0 and "HANG" not in p.stdout, p.stdout + p.stderr
    assert int(p.stdout.split()[-1]) >= 4      # at least one interrupt in each kind of hand-off


@pytest.mark.parametrize("where", ["set-up", "first frame", "mid-run"])
def test_an_interrupted_run_leaves_no_worker_behind(where, monkeypatch):
    scene = replace(load_scene(SCENES / "fig12-tracking.toml"), duration_s=2.0)
    loop = ClosedLoop(scene)

    def interrupt(*_):
        raise KeyboardInterrupt

    if where == "set-up":       # after the first draws were handed to the worker
        real = loop.sensor.draw_ahead
        monkeypatch.setattr(loop.sensor, "draw_ahead", lambda ahead: (real(ahead), interrupt()))
        progress = None
    else:
        progress = interrupt if where == "first frame" else (lambda k, n: k == 12 and interrupt())
    with pytest.raises(KeyboardInterrupt):
        loop.run(progress, ahead=True)
    assert loop._scan_ahead is None
    assert not [t.name for t in threading.enumerate() if t.name.startswith("sim-ahead")]
