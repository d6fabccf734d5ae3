"""Dataset folders of numpy frames named by their time (the MMAUD layout).

``<unix time>.npy`` per scan, e.g. ``1706255621.614239.npy``: an (N, 3) float array of x, y, z [m]
in the sensor frame; rows of zeros are padding (MMAUD pads every frame to 24000 rows).  Frames are
read in time order (the time in the name, read exactly: :func:`~foveatrack.sources.stamps.time_from_file_stem`;
µs or ns since 1970 as digits only, e.g. ``1717243800005000.npy``, are read too).
An (N, 4) array's fourth column is taken as intensity and dropped.  A file cut short (its writer
killed, a copy interrupted) is read to its last whole point, with one warning, as a PCD file is.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from foveatrack.errors import UserError
from foveatrack.sources.stamps import (StampedFrame, check_rate, cut_short, frame_from_cloud, time_from_file_stem,
                                       warn_stderr)


def timed_files(folder: Path, suffix: str) -> list[tuple[int, Path]]:
    """``(stamp_ns, path)`` of the files ``<unix time><suffix>`` in ``folder``, oldest first; a
    UserError naming the folder when there are none, or the file when one is not named by a time
    or is named in another unit than the rest (:func:`~foveatrack.sources.stamps.time_from_file_stem`)."""
    files = [f for f in folder.iterdir() if f.is_file() and f.suffix.lower() == suffix]
    if not files:
        raise UserError(f"{folder}: no {suffix} files (an empty folder for frames)")
    out, units = [], {}
    for f in sorted(files):
        got = time_from_file_stem(f.name[: -len(suffix)])
        if got is None:
            raise UserError(f"{f}: the file name is not a time since 1970 before 2262 (<unix seconds>"
                            f"[.fraction]{suffix}, or digits only: 10 seconds, 13 ms, 16 µs, 19 ns expected)")
        ns, unit = got
        units.setdefault(unit, f)
        if len(units) > 1:
            (u0, f0), = ((u, g) for u, g in units.items() if u != unit)
            raise UserError(f"{f}: the name reads as {unit} since 1970 but {f0.name}'s as {u0} (a name's unit "
                            f"is given by its digits); give a folder of names in one unit")
        out.append((ns, f))
    out.sort()
    for (a, fa), (b, fb) in zip(out, out[1:]):
        if a == b:
            raise UserError(f"{fb}: has the same time as {fa.name}")
    return out


class NpyFolderSource:
    """Iterable of ``(arrival_s, Frame)`` over a folder of ``<unix time>.npy`` frames."""

    kind = "npy folder"

    def __init__(self, folder, rate_hz: float = 10.0, warn=None):
        self.path = Path(folder)
        self.rate_hz = check_rate(rate_hz)
        self.files = timed_files(self.path, ".npy")
        #: where a file cut short is said (one line each; default: stderr)
        self.warn = warn or warn_stderr

    def __len__(self) -> int:
        return len(self.files)

    def __iter__(self):
        for ns, f in self.files:
            a = _read_npy(f, self.warn)
            if a.ndim != 2 or a.shape[1] not in (3, 4) or a.dtype.kind not in "fiu":
                raise UserError(f"{f}: expected an (N, 3) array of x, y, z numbers, "
                                f"got shape {a.shape} of {a.dtype}")
            fr = frame_from_cloud(ns, a[:, :3], self.rate_hz)
            yield StampedFrame(fr.t_end_s, fr)


def _read_npy(f: Path, warn) -> np.ndarray:
    """The array of a ``.npy`` file; one cut short (its header whole, its body not) is read to its
    last whole row, and ``warn`` says how many of the header's rows are missing."""
    try:
        return np.load(f, allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        cut = _npy_cut_short(f)
        if cut is None:
            why = "it holds pickled objects" if "pickle" in str(exc) else " ".join(str(exc).split())[:160]
            raise UserError(f"{f}: not a readable .npy array of numbers ({why})") from None
    a, said = cut
    warn(cut_short(f, a.shape[0], said))
    return a


def _npy_cut_short(f: Path) -> tuple[np.ndarray, int] | None:
    """``(its whole rows, the rows its header gives)`` of a 2-D numeric ``.npy`` whose body is
    shorter than its header says; None for any other damage (numpy's own error is then the one said)."""
    fmt = np.lib.format
    try:
        with open(f, "rb") as fh:
            read_header = {(1, 0): fmt.read_array_header_1_0, (2, 0): fmt.read_array_header_2_0}[fmt.read_magic(fh)]
            shape, fortran, dtype = read_header(fh)
            body = fh.read()
    except Exception:
        return None
    if dtype.hasobject or len(shape) != 2 or dtype.itemsize == 0:
        return None
    row = shape[1] * dtype.itemsize
    if len(body) >= shape[0] * row:
        return None
    if fortran or row == 0:       # column after column: no whole point is left
        return np.empty((0, shape[1]), dtype), shape[0]
    n = len(body) // row
    return np.frombuffer(body[: n * row], dtype=dtype).reshape(n, shape[1]), shape[0]
