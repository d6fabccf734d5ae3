"""Digests of whole closed-loop runs, to show that a speed change left every bit of a run alone.

Prints JSON: per run, a digest of the per-frame log and one of every frame's points (xyz, times,
reflectivity), the commands and the bytes sent, then the ray counters.  Run it before and after a
change (e.g. on the old commit exported with ``git archive`` and put first on ``PYTHONPATH``) and
compare the two outputs: they must be equal.

Runs: fig12 and its hall variant (as ``scripts/bench_closed_loop.py`` builds it) over 30 s, on one
thread and worked ahead; fig12 with the head pose from a 1 ms grid and from the head model per point;
fig12 with every sensor effect (angular noise, dropouts, sunlight too) and a circling target, and
with the beam footprint; every shipped scene (up to 8 s), one thread and ahead.

Usage: python scripts/digest_runs.py > digests.json
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
import tomllib
from dataclasses import replace
from pathlib import Path


os.environ.setdefault("NUMBA_NUM_THREADS", "1")

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_closed_loop import hall_scene  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "determinism"))
from digests import _digest as array_digest  # noqa: E402
from sim.loop import ClosedLoop  # noqa: E402
from sim.scene import load_scene, scene_from_mapping  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
FIG12 = ROOT / "scenes" / "fig12-tracking.toml"


def _digest(*arrays) -> str:
    """The determinism tests' digest of arrays (dtype, shape and bytes), shortened for printing."""
    return array_digest(*arrays)[:16]


def run_digest(scene, ahead: bool = False, **kw) -> str:
    frames = hashlib.sha256()

    def hook(frame, out, loop):
        frames.update(_digest(frame.xyz, frame.t_ns, frame.reflectivity).encode())
        if loop.last_sent:
            frames.update(loop.last_sent[1] + repr(loop.last_sent[0]).encode())
        frames.update(repr((out.command, out.state, out.world_xyz, out.world_sigma_m)).encode())

    loop = ClosedLoop(scene, frame_hook=hook, **kw)
    log = loop.run(ahead=ahead)
    return (f"{_digest(*(log[k] for k in sorted(log)))} {frames.hexdigest()[:16]} "
            f"{loop.rays_total} {loop.rays_cast_targets} {loop.bytes_sent}")


def main() -> None:
    out = {}
    hall = hall_scene(FIG12)
    fig12 = load_scene(FIG12)
    for name, scene in (("fig12", fig12), ("hall", hall)):
        out[name] = run_digest(scene)
        out[f"{name}/ahead"] = run_digest(scene, True)
    out["fig12/grid"] = run_digest(replace(fig12, duration_s=5.0), head_grid_s=0.001)
    out["fig12/per-point"] = run_digest(replace(fig12, duration_s=3.0), head_grid_s=0.0)
    data = tomllib.loads(FIG12.read_text())
    data["scene"]["effects"] = ["range_noise", "motor_speed_noise", "return_probability", "angular_noise",
                                "dropouts", "sunlight"]
    data["target"][0]["trajectory"] = {"type": "circle", "centre_m": [14.0, 0.0, 1.0], "radius_m": 3.0,
                                       "speed_m_s": 2.0}
    every = replace(scene_from_mapping(data, "every effect"), duration_s=10.0)
    out["every-effect"] = run_digest(every)
    out["every-effect/ahead"] = run_digest(every, True)
    data["scene"]["effects"] = ["range_noise", "beam_footprint", "dropouts"]
    footprint = replace(scene_from_mapping(data, "beam footprint"), duration_s=5.0)
    out["footprint"] = run_digest(footprint)
    out["footprint/ahead"] = run_digest(footprint, True)
    for path in sorted((ROOT / "scenes").glob("*.toml")):
        scene = load_scene(path)
        scene = replace(scene, duration_s=min(scene.duration_s, 8.0))
        out[path.stem] = run_digest(scene)
        out[f"{path.stem}/ahead"] = run_digest(scene, True)
    json.dump(out, sys.stdout, indent=1)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
