"""Folders of PCD files, one per scan, named by time (``<unix time>.pcd``), read with ``pypcd4``
(every header version, ascii / binary / binary_compressed bodies).  Fields x, y, z are needed;
``intensity`` (0..255) is kept as reflectivity; a per-point time is not read (PCD has no standard
field for it), so points are at the file's time."""

from __future__ import annotations

import io
import re
from pathlib import Path

import numpy as np

from foveatrack.errors import UserError
from foveatrack.sources.npy_folder import timed_files
from foveatrack.sources.stamps import StampedFrame, check_rate, cut_short, frame_from_cloud, warn_stderr


class PcdFolderSource:
    kind = "pcd folder"

    def __init__(self, folder, rate_hz: float = 10.0, warn=None):
        self.path = Path(folder)
        self.rate_hz = check_rate(rate_hz)
        self.files = timed_files(self.path, ".pcd")
        #: where a scan cut short is said (one line each; default: stderr)
        self.warn = warn or warn_stderr

    def __len__(self) -> int:
        return len(self.files)

    def __iter__(self):
        for ns, f in self.files:
            pc, held, said = _read_pcd(f)
            fields = pc.fields
            if held < said:
                # a scan cut short (its writer killed, a copy interrupted): its whole points, said once
                self.warn(cut_short(f, held, said))
            missing = [k for k in ("x", "y", "z") if k not in fields]
            if missing:
                raise UserError(f"{f}: the PCD has no field {', '.join(missing)} (fields: {', '.join(fields)})")
            xyz = pc.numpy(("x", "y", "z")).astype(np.float64, copy=False)
            refl = None
            if "intensity" in fields:
                refl = np.clip(pc.numpy(("intensity",))[:, 0], 0, 255).astype(np.uint8)
            fr = frame_from_cloud(ns, xyz, self.rate_hz, reflectivity=refl)
            yield StampedFrame(fr.t_end_s, fr)


def _read_pcd(f: Path):
    """``(PointCloud, points read, points its header gives)``.  A body cut short is read to its last
    whole point (ascii: its last whole line; binary: whole points of SIZE x COUNT bytes) rather than
    refused (pypcd4: "buffer size must be a multiple of element size") or read with a number cut in
    half; a compressed body cut short cannot be, and is refused as unreadable."""
    from pypcd4 import PointCloud

    def parse(data: bytes):
        try:
            return PointCloud.from_fileobj(io.BytesIO(data))
        except Exception as exc:   # pypcd4 raises many kinds (pydantic, ValueError, IndexError) on a bad file
            raise UserError(f"{f}: not a readable PCD file ({_pcd_problem(exc)})") from None

    data = Path(f).read_bytes()
    m = re.search(rb"^DATA[ \t]+(\w+)[^\n]*\n", data, re.M)
    if m is None:
        return (pc := parse(data)), pc.points, pc.points
    head, body, kind = data[:m.end()], data[m.end():], m.group(1).lower()

    def key(name: bytes) -> list[bytes]:
        k = re.search(rb"^" + name + rb"[ \t]+([^\n]*)", head, re.M)
        return k.group(1).split() if k else []

    try:
        said = int(key(b"POINTS")[0])
        point_bytes = sum(int(a) * int(b) for a, b in zip(key(b"SIZE"), key(b"COUNT") or [b"1"] * len(key(b"SIZE"))))
    except (IndexError, ValueError):
        return (pc := parse(data)), pc.points, pc.points
    if kind == b"ascii":
        lines = body.split(b"\n")
        if body and not body.endswith(b"\n"):
            lines = lines[:-1]                 # the last line cut in the middle of a number
        whole = [ln for ln in lines if ln.strip()]
        n = min(len(whole), said)
        keep = b"\n".join(whole[:n]) + b"\n"
    elif kind == b"binary" and point_bytes > 0:
        n = min(len(body) // point_bytes, said)
        keep = body[:n * point_bytes]
    else:
        return (pc := parse(data)), pc.points, said
    if n == said:
        pc = parse(data)
        return pc, pc.points, said
    head = re.sub(rb"^(POINTS|WIDTH)[ \t]+\d+", lambda k: k.group(1) + b" " + str(n).encode(), head, flags=re.M)
    head = re.sub(rb"^HEIGHT[ \t]+\d+", b"HEIGHT 1", head, flags=re.M)
    return parse(head + keep), n, said


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
