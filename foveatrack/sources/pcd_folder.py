"""Folders of PCD files, one per scan, named by time (``<unix time>.pcd``), read with ``pypcd4``
(every header version, ascii / binary / binary_compressed bodies).  Fields x, y, z are needed;
``intensity`` (0..255) is kept as reflectivity; a per-point time is not read (PCD has no standard
field for it), so points are at the file's time."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from foveatrack.errors import UserError
from foveatrack.sources.npy_folder import timed_files
from foveatrack.sources.stamps import StampedFrame, check_rate, frame_from_cloud


class PcdFolderSource:
    kind = "pcd folder"

    def __init__(self, folder, rate_hz: float = 10.0):
        self.path = Path(folder)
        self.rate_hz = check_rate(rate_hz)
        self.files = timed_files(self.path, ".pcd")

    def __len__(self) -> int:
        return len(self.files)

    def __iter__(self):
        from pypcd4 import PointCloud

        for ns, f in self.files:
            try:
                pc = PointCloud.from_path(f)
                fields = pc.fields
            except Exception as exc:   # pypcd4 raises many kinds (pydantic, ValueError, IndexError) on a bad file
                raise UserError(f"{f}: not a readable PCD file ({_pcd_problem(exc)})") from None
            missing = [k for k in ("x", "y", "z") if k not in fields]
            if missing:
                raise UserError(f"{f}: the PCD has no field {', '.join(missing)} (fields: {', '.join(fields)})")
            xyz = pc.numpy(("x", "y", "z")).astype(np.float64, copy=False)
            refl = None
            if "intensity" in fields:
                refl = np.clip(pc.numpy(("intensity",))[:, 0], 0, 255).astype(np.uint8)
            fr = frame_from_cloud(ns, xyz, self.rate_hz, reflectivity=refl)
            yield StampedFrame(fr.t_end_s, fr)


def _pcd_problem(exc: Exception) -> str:
    """What was wrong, in a line: a header pypcd4's validation refused names its keys."""
    errors = getattr(exc, "errors", None)
    if callable(errors):   # pydantic's ValidationError: the header's keys that are missing or wrong
        try:
            keys = sorted({str(e["loc"][0]) for e in errors() if e.get("loc")})
        except Exception:
            keys = []
        if keys:
            return f"bad header: {', '.join(k.upper() for k in keys)} missing or invalid"
    s = " ".join(str(exc).split())
    return s[:160] if s else type(exc).__name__
