""""Same seed, same scene, same bits", and what it means across machines.

The promise (README, "Reproducibility"):

* On one machine and install, a scene and seed give the same run to the bit, whatever the chunking of
  the scan (100 ms frames, lidar packets), the test order or what ran before in the process.  This
  holds by construction: the numba kernels are compiled without fast-math, so a vector lane and the
  scalar remainder loop compute the same IEEE operations and no point's result depends on where a
  chunk starts or on the vector width.
* Across x86-64 machines the numba kernels give the same bits whatever the SIMD units (checked here by
  pinning numba's code generation to the SSE2-only ``generic`` target).  What can still differ is the
  C library's and numpy's transcendental functions (sin, cos, atan2, ...), which pick CPU-specific
  variants (FMA, AVX2, AVX-512).  With those emulated as on an SSE2-only CPU as well, the exact scan
  model and every shipped scene's closed loop stay identical (the truth's angles, made by glibc's
  atan2, to 1e-9 deg: its FMA and SSE2 variants differ in the last bit; the tracker's bearings use the
  same atan2, so a command could differ where a bearing falls within an ulp of a speed byte's boundary --
  that part holds by measurement, not by construction); the paraxial model and the slow motor
  drift (which call the C library's sin and cos) agree within ``ULP_PARAXIAL_DRIFT``.
* numpy's BLAS (OpenBLAS, built for every x86-64 core and picking its kernels at load) would sum a
  product in another order, or with fused multiply-adds, on another core; the per-frame and set-up
  products are therefore written out in a fixed order (:mod:`foveatrack.fixed_order`), and every
  digest must stay the same with OpenBLAS told (``OPENBLAS_CORETYPE``) to use each kernel set this CPU
  can run: Haswell (also what Zen gets), SkylakeX, Sandybridge, Nehalem and Prescott (an SSE2/SSE3 one).

Each comparison runs ``digests.py`` in fresh interpreters; ``.ci/run`` also runs this file with
``NUMBA_CPU_NAME=generic`` in the environment (the in-process digests then come from that target).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytestmark = [pytest.mark.determinism, pytest.mark.slow]

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
EXACT_KEYS_PREFIX = ("scan/mid40-noise", "scan/horizon-noise", "loop/")
# Measured on an AVX-512 machine against its emulated SSE2 self (glibc 2.36): the paraxial directions
# differ in 0.12 % of the points by at most 0.5 ulp of 1, the drift's in 0.08 % by at most 6.4 ulp of 1
# (a 1-ulp phase difference is amplified by the refraction); 16 leaves room for another libm.
ULP_PARAXIAL_DRIFT = 16

sys.path.insert(0, str(HERE))
import digests  # noqa: E402


def _run_digests(env_changes: dict[str, str | None], arrays: Path | None = None,
                 stderr: list[str] | None = None) -> dict[str, str]:
    env = dict(os.environ)
    for k, v in env_changes.items():
        if v is None:
            env.pop(k, None)
        else:
            env[k] = v
    cmd = [sys.executable, str(HERE / "digests.py")] + (["--arrays", str(arrays)] if arrays else [])
    out = subprocess.run(cmd, env=env, cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr[-3000:]
    if stderr is not None:
        stderr.append(out.stderr)
    return json.loads(out.stdout)


def _old_cpu_env() -> dict[str, str | None]:
    """numba, numpy, OpenBLAS and glibc each told to act as on an x86-64 CPU with SSE2 only (no AVX,
    no FMA; OpenBLAS's oldest kernels are Prescott's, SSE3)."""
    from numpy._core import _multiarray_umath as mu

    found = [t for t in mu.__cpu_dispatch__ if mu.__cpu_features__.get(t)]
    env = {"NUMBA_CPU_NAME": "generic", "NUMBA_CPU_FEATURES": None,
           "OPENBLAS_CORETYPE": "Prescott",
           "GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX512F,-AVX512DQ,-AVX512VL,-AVX2,-FMA,-AVX"}
    if found:   # numpy refuses to disable a feature it would not dispatch to
        env["NPY_DISABLE_CPU_FEATURES"] = " ".join(found)
    return env


@pytest.fixture(scope="module")
def native(tmp_path_factory):
    path = tmp_path_factory.mktemp("native") / "scan.npz"
    return _run_digests({"NUMBA_CPU_NAME": None, "NUMBA_CPU_FEATURES": None, "OPENBLAS_CORETYPE": None},
                        path), path


def test_chunking_and_a_fresh_interpreter_change_no_bit(native):
    digests_native, _ = native
    for key, value in digests_native.items():
        if key.endswith("/chunked"):
            assert value == digests_native[key.removesuffix("/chunked")], key
    # this process (whatever ran before it here, and under whatever numba target pytest was started)
    inproc = {**digests.scan_digests(), **digests.loop_digests()}
    if os.environ.get("NUMBA_CPU_NAME", "host") in ("host", ""):
        assert inproc == digests_native
    else:   # started under a pinned target: the kernels must still give the native bits
        assert inproc == digests_native, "a numba CPU target changed a result"


def test_numba_generic_target_gives_the_native_bits(native):
    digests_native, _ = native
    generic = _run_digests({"NUMBA_CPU_NAME": "generic", "NUMBA_CPU_FEATURES": None})
    differ = sorted(k for k in digests_native if generic[k] != digests_native[k])
    assert differ == []


def test_an_emulated_sse2_cpu_gives_the_same_runs(native, tmp_path):
    digests_native, native_npz = native
    old = _run_digests(_old_cpu_env(), tmp_path / "scan.npz")
    same_required = [k for k in digests_native if k.startswith(EXACT_KEYS_PREFIX)]
    assert len(same_required) >= 4 + 8
    assert [k for k in same_required if old[k] != digests_native[k]] == []
    a, b = np.load(native_npz), np.load(tmp_path / "scan.npz")
    for name in ("mid40-paraxial", "prototype-drift"):
        # unit directions: in ulps of 1 (2.2e-16), the scale of the vector, not of a small component
        ulp = np.max(np.abs(a[name] - b[name])) / np.spacing(1.0)
        assert ulp <= ULP_PARAXIAL_DRIFT, (name, float(ulp))


# OpenBLAS core names -> what this CPU must have to run their kernels (numpy's feature names)
OPENBLAS_CORES = {"Haswell": ("AVX2", "FMA3"), "Zen": ("AVX2", "FMA3"), "SkylakeX": ("AVX512_SKX",),
                  "Sandybridge": ("AVX",), "Nehalem": ("SSE42",), "Prescott": ()}


def test_every_openblas_kernel_set_gives_the_native_bits(native):
    """The kernels OpenBLAS would pick on a Haswell, Zen, Skylake-X, Sandy Bridge, Nehalem or SSE3 CPU
    change no digest (those this CPU cannot run are left out).  ``OPENBLAS_VERBOSE=2`` makes OpenBLAS
    name the kernels it took, so a build that ignored the request could not pass unseen."""
    from numpy._core import _multiarray_umath as mu

    digests_native, _ = native
    cores = [c for c, need in OPENBLAS_CORES.items() if all(mu.__cpu_features__.get(f) for f in need)]
    taken, differ = set(), {}
    for core in cores:
        err: list[str] = []
        got = _run_digests({"OPENBLAS_CORETYPE": core, "OPENBLAS_VERBOSE": "2"}, stderr=err)
        used = [line.split(":", 1)[1].strip() for line in err[0].splitlines() if line.startswith("Core:")]
        assert used, f"OpenBLAS did not say which kernels it took for {core}: {err[0][-500:]}"
        taken.update(used)
        differ[core] = sorted(k for k in digests_native if got[k] != digests_native[k])
    assert differ == {c: [] for c in cores}
    assert len(taken) >= 2, taken   # at least two kernel sets really compared (SSE3 runs anywhere)
