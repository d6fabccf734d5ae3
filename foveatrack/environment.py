"""What a bug report or a benchmark figure needs to say about the machine and the install.

``foveatrack --version`` and every benchmark script's header print :func:`describe`: the package, Python,
the pinned dependencies' installed versions, the CPU's SIMD units and numba's code-generation target
(``NUMBA_CPU_NAME``).  Results are the same to the bit across SIMD units (see the README's
"Reproducibility"), but speed is not: a figure without its machine says little.
"""

from __future__ import annotations

import os
import platform
import sys

# The runtime dependencies whose versions matter for results and speed (pyproject.toml pins them).
DEPENDENCIES = ("numpy", "scipy", "numba", "llvmlite", "matplotlib", "pyserial", "tqdm", "mcap")


def installed_version(dist: str) -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(dist)
    except PackageNotFoundError:
        return "not installed"


def simd_units() -> list[str]:
    """The x86 vector extensions this CPU reports (AVX, AVX2, FMA, AVX-512 ...), from /proc/cpuinfo;
    empty where that file is not there (other systems)."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("flags"):
                    flags = set(line.split(":", 1)[1].split())
                    return sorted(f for f in flags if f.startswith(("avx", "fma", "sse4")))
    except OSError:
        pass
    return []


def describe() -> str:
    """One paragraph: versions, CPU, numba target."""
    from foveatrack import __version__

    deps = ", ".join(f"{d} {installed_version(d)}" for d in DEPENDENCIES)
    units = simd_units()
    cpu = f"{platform.machine()}, SIMD: {' '.join(units) if units else 'unknown'}"
    target = os.environ.get("NUMBA_CPU_NAME") or "host"
    return (f"foveatrack {__version__} (Python {sys.version.split()[0]}; {deps})\n"
            f"CPU {cpu}; numba target {target}; {os.cpu_count()} cores")
