"""The scene-driven lidar source: the same points as the closed loop, pose following, truth tailing."""

import json
import math

import numpy as np
import pytest

from sim.lidar_server import SceneSource, TruthTail
from sim.loop import ClosedLoop
from sim.scene import scene_from_mapping


def _scene(target_at, frozen=True, ground=True):
    d = {"scene": {"name": "t", "duration_s": 1.0, "seed": 1}, "lidar": {"preset": "mid40"},
         "gimbal": {"frozen": frozen},
         "target": [{"geometry": "sphere", "radius_m": 0.4,
                     "trajectory": {"type": "straight", "start_m": list(target_at), "velocity_m_s": [0.0, 0.0, 0.0]}}]}
    if ground:
        d["background"] = [{"type": "ground", "height_m": 1.5}]
    return scene_from_mapping(d)


@pytest.mark.determinism
def test_points_equal_the_closed_loop_frame():
    scene = scene_from_mapping({
        "scene": {"name": "t", "duration_s": 1.0, "seed": 1}, "lidar": {"preset": "mid40"}, "gimbal": {"frozen": True},
        "target": [{"geometry": "quadrotor", "trajectory": {"type": "straight", "start_m": [8.0, 1.0, 0.3],
                                                             "velocity_m_s": [0.0, -2.0, 0.1]}}],
        "background": [{"type": "ground", "height_m": 1.5}]})
    frame, _ = ClosedLoop(scene).step(0.0, 0.1)
    xyz, refl, t_ns = SceneSource(scene)(0, 100_000_000)
    assert frame.n_points > 1000
    assert np.array_equal(t_ns, frame.t_ns) and np.array_equal(xyz, frame.xyz)
    assert np.array_equal(refl, frame.reflectivity)
    # batches of any size give the same stream
    src = SceneSource(scene)
    parts = [src(k * 7_000_000, min((k + 1) * 7_000_000, 100_000_000)) for k in range(15)]
    assert np.array_equal(np.concatenate([p[2] for p in parts]), t_ns)
    assert np.array_equal(np.concatenate([p[0] for p in parts]), xyz)


def test_follows_the_head_pose():
    """Panning the head by p sees a target at R_z(p) c exactly as an unpanned head sees c (the
    ground is invariant under pan)."""
    c = np.array([12.0, 0.0, 1.0])
    p = math.radians(20.0)
    rc = [c[0] * math.cos(p) - c[1] * math.sin(p), c[0] * math.sin(p) + c[1] * math.cos(p), c[2]]
    a = SceneSource(_scene(c))(0, 100_000_000)
    b = SceneSource(_scene(rc), pose=lambda t: (np.full(np.shape(t), 20.0), np.zeros(np.shape(t))))(0, 100_000_000)
    assert np.array_equal(a[2], b[2])
    assert np.allclose(a[0], b[0], atol=1e-9)
    on_target = np.linalg.norm(a[0] - c, axis=1) < 0.5
    assert on_target.sum() > 20


def test_truth_tail_interpolates_extrapolates_and_follows_a_restart(tmp_path):
    f = tmp_path / "truth.jsonl"

    def row(t, pan, tilt, vp=0.0, vt=0.0):
        return json.dumps({"t_s": t, "pan_deg": pan, "tilt_deg": tilt, "pan_speed_deg_s": vp, "tilt_speed_deg_s": vt})

    with open(f, "w") as fh:
        for k in range(11):
            fh.write(row(0.02 * k, 179.0 + 0.2 * k, -0.05 * k, 10.0, -2.5) + "\n")   # crosses +-180
        fh.write('{"t_s": 0.3, "pan')   # a partial line is not read yet
    tail = TruthTail(str(f), clock_zero=100.0, extrapolate_s=0.1)
    tail.poll(now_mono=100.25)
    assert tail.lines == 11
    pan, tilt = tail.pose_at_mono(np.array([100.01, 100.1, 100.2, 100.25, 101.0]))
    assert np.allclose(pan[:2], [179.1, 180.0]) and np.isclose(pan[2], -179.0)   # unwrapped, then wrapped
    assert np.isclose(pan[3], -179.0 + 10.0 * 0.05)         # extrapolated with its speed
    assert np.isclose(pan[4], -179.0 + 10.0 * 0.1)          # ... at most extrapolate_s
    assert np.allclose(tilt[:3], [-0.025, -0.25, -0.5])
    # the head restarts: the file is rewritten from t_s = 0 at a new pose
    with open(f, "w") as fh:
        fh.write(row(0.0, 10.0, 1.0) + "\n" + row(0.02, 10.0, 1.0) + "\n")
    tail.poll(now_mono=101.0)
    assert tail.restarts == 1
    assert np.allclose(tail.pose_at_head_time(np.array([0.01])), [[10.0], [1.0]])
    # without the clock zero it is estimated from when lines are read
    est = TruthTail(str(f))
    est.poll(now_mono=50.03)
    assert np.isclose(est.zero, 50.03 - 0.02)


_STREAM_AFTER_WARM_UP = """
import sys
import numba
import sim.scan.kernels, sim.sensor_kernels, sim.world.kernels
from sim.lidar_server import SceneSource, warm_up_kernels
from sim.scene import load_scene

def signatures():
    return {f"{m.__name__}.{k}": len(v.signatures) for m in (sim.scan.kernels, sim.sensor_kernels, sim.world.kernels)
            for k, v in vars(m).items() if isinstance(v, numba.core.registry.CPUDispatcher)}

scene = load_scene(sys.argv[1])
warm_up_kernels(scene)
before = signatures()
src = SceneSource(scene)
for k in range(30):                         # 3 s of stream in 100 ms chunks, the UAV in view
    src(k * 100_000_000, (k + 1) * 100_000_000)
after = signatures()
print(src.points_on_target, sorted(k for k in after if after[k] != before.get(k, 0)))
"""


def test_warm_up_covers_every_kernel_of_the_stream():
    """``lidar serve`` compiles its kernels before going real time; a kernel first met mid-stream
    (the moving-body cast, once a ray reaches the UAV) stalled it ~2 s on a fresh install, and the
    daemon got the data late, in a burst.  In a fresh interpreter, streaming after the warm-up
    compiles nothing more."""
    import subprocess
    import sys
    from pathlib import Path

    scene = Path(__file__).with_name("scene_track.toml")
    out = subprocess.run([sys.executable, "-c", _STREAM_AFTER_WARM_UP, str(scene)], capture_output=True, text=True,
                         check=True).stdout.split(maxsplit=1)
    assert int(out[0]) > 0, "the stream reached the UAV"
    assert out[1].strip() == "[]", f"compiled mid-stream: {out[1]}"
