"""SHA-256 digests of what "same seed, same bits" promises: scans and closed-loop runs.

Run as a script (``python tests/determinism/digests.py``) it prints the digests as JSON; the tests run it
in fresh interpreters with numba's code generation pinned to different CPU targets
(``NUMBA_CPU_NAME=generic``: SSE2 only, no FMA; and the machine's own, e.g. AVX-512) and compare.

What is digested:

* the scan model's directions, times and statuses: the fused exact kernel with motor speed noise
  (mid40, horizon), the composed path with the slow drift, and the paraxial model, each in one call
  and in uneven chunks (the chunked digests must equal the whole ones);
* every shipped scene's closed loop over 1.5 s of virtual time: the per-frame log (true and estimated
  poses, detections, commands, points), which covers the world, sensor, tracker and head kernels.
"""

from __future__ import annotations

import hashlib
import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def _digest(*arrays) -> str:
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(str(a.dtype).encode() + str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def scan_digests(arrays: dict | None = None) -> dict[str, str]:
    """Digests of the scan cases; ``arrays``, if given, receives each case's directions."""
    from sim.scan.model import ScanModel
    from sim.scan.optics import SpeedNoise
    from sim.scan.presets import PRESETS

    cases = {
        "mid40-noise": lambda: ScanModel(PRESETS["mid40"], speed_noise=SpeedNoise(sigma_frac=0.01, segment_s=0.0037),
                                         rng=np.random.default_rng(3)),
        "horizon-noise": lambda: ScanModel(PRESETS["horizon"], speed_noise=SpeedNoise(sigma_frac=0.01, segment_s=0.0037),
                                           rng=np.random.default_rng(3)),
        "prototype-drift": lambda: ScanModel(PRESETS["prototype"], speed_noise=SpeedNoise(drift_frac=0.001),
                                             rng=np.random.default_rng(5)),
        "mid40-paraxial": lambda: ScanModel(PRESETS["mid40"], model="paraxial"),
    }
    k0, n = 123_457, 30_001
    cuts = [k0, k0 + 1, k0 + 97, k0 + 256 * 7 + 3, k0 + 20_000, k0 + n]
    out = {}
    for name, make in cases.items():
        whole = make().scan(k0, n)
        out[f"scan/{name}"] = _digest(whole.direction, whole.t_ns, whole.status)
        if arrays is not None:
            arrays[name] = whole.direction
        m = make()
        parts = [m.scan(a, b - a) for a, b in zip(cuts[:-1], cuts[1:])]
        out[f"scan/{name}/chunked"] = _digest(np.concatenate([p.direction for p in parts]),
                                              np.concatenate([p.t_ns for p in parts]),
                                              np.concatenate([p.status for p in parts]))
    return out


# The truth's angles (the target off the lidar axis, its azimuth and elevation) are the log's analysis
# columns, made by the C library's atan2 from the true poses; glibc's FMA and SSE2 variants of atan2
# differ in the last bit (seen: drone-in-fog, frame 10, 4.155159040759983 vs ...982 deg), so these three
# are digested rounded to 1e-9 deg.  Every simulated quantity (points, poses, detections, commands) is
# digested to the bit.
TRUTH_ANGLES = ("true_error_deg", "true_az_deg", "true_el_deg")


def _as_digested(key: str, values):
    return np.round(np.asarray(values, dtype=float), 9) if key in TRUTH_ANGLES else values


def loop_digests(seconds: float = 1.5) -> dict[str, str]:
    from sim.loop import ClosedLoop
    from sim.scene import load_scene

    out = {}
    for path in sorted((ROOT / "scenes").glob("*.toml")):
        scene = replace(load_scene(path), duration_s=seconds)
        log = ClosedLoop(scene).run()
        out[f"loop/{path.stem}"] = _digest(*(_as_digested(k, log[k]) for k in sorted(log)))
    return out


def main(argv: list[str]) -> None:
    """``digests.py [--arrays OUT.npz]``: print the digests; also save the scan directions."""
    arrays = {} if argv[:1] == ["--arrays"] else None
    json.dump({**scan_digests(arrays), **loop_digests()}, sys.stdout, indent=1, sort_keys=True)
    sys.stdout.write("\n")
    if arrays is not None:
        np.savez(argv[1], **arrays)


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    main(sys.argv[1:])
