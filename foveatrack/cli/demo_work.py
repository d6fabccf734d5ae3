"""The work the demo, `foveatrack warmup` and the first compile's processes share: the shipped scenes,
the demo's scan figures and the recording's packing warm-up.  Below the command modules, so the
compile processes (:mod:`foveatrack.cli.kernel_compile`), which the commands start, import no command.
"""

from __future__ import annotations

from pathlib import Path

from foveatrack.errors import UserError

DEFAULT_SCENE = "fig12-tracking.toml"


def shipped_scene(name: str) -> Path:
    """Path of a scene shipped in the repository's ``scenes/`` folder."""
    path = Path(__file__).resolve().parents[2] / "scenes" / name
    if not path.is_file():
        raise UserError(f"shipped scene {name} not found at {path}; run from a checkout (pip install -e .)")
    return path


def scan_analyses(optics, short: bool = False) -> dict:
    """The demo's scan figures for ``optics``: the radial density (exact and paraxial, two-prism
    scanners only) and the voxel coverage with 1 % speed noise.  ``short``: a few milliseconds of
    each (the same kernels in the same types; for the first compile, :mod:`foveatrack.cli.kernel_compile`)."""
    import numpy as np

    from sim.scan.coverage import voxel_coverage
    from sim.scan.density import radial_density
    from sim.scan.model import ScanModel
    from sim.scan.optics import SpeedNoise

    density_s, coverage_s = (0.01, 0.01) if short else (1.0, 2.0)
    out = {}
    if len(optics.prisms) == 2:
        out["density_exact"] = radial_density(ScanModel(optics), density_s)
        out["density_paraxial"] = radial_density(ScanModel(optics, model="paraxial"), density_s)
    noisy = ScanModel(optics, speed_noise=SpeedNoise(), rng=np.random.default_rng(0))
    out["coverage"] = voxel_coverage(noisy, coverage_s)
    return out


def warm_recording_kernels() -> None:
    """The recording's point packing (``simulate --out``, the daemon): a frame on the mm grid (its
    kernels; a frame off the grid is packed by numpy), as the recording's child process warms it."""
    import numpy as np

    from foveatrack.recording.pack_kernels import pack_points

    pack_points(np.zeros((2, 3)), 0, np.zeros(2, np.int64), np.zeros(2, np.uint8))
