"""An output file that appears under its name only when it is whole.

:func:`written_whole` gives a temporary file beside the output to write, and renames it onto the
output's name (``os.replace``, atomic on one file system) only when the writing ended without an
exception; an exception -- KeyboardInterrupt too -- removes it.  A Ctrl-C during an export left a
CSV with 917 505 of its 1 251 727 lines, and an NPZ that would not decompress, under the names a
finished export has: ``--overwrite`` was then asked for as if it were one.  A core module: the
recording layer and the Livox layer both write through it.
"""

from __future__ import annotations

import os
import secrets
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator


@contextmanager
def written_whole(path: str | os.PathLike) -> Iterator[Path]:
    """The path of an empty temporary file in ``path``'s directory (a hidden name, ``.NAME.<8 hex digits>.tmp``),
    for the caller to write (open it with "w"/"wb"; it keeps the mode a new file gets under the umask,
    or the mode of the file it replaces); moved onto ``path`` when the block ends, removed if it raises.
    A symlink at ``path`` is written through: its target is replaced."""
    final = Path(os.path.realpath(path))
    tmp = None
    try:
        while tmp is None:
            name = final.with_name(f".{final.name}.{secrets.token_hex(4)}.tmp")
            try:
                os.close(os.open(name, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
            except FileExistsError:
                continue
            tmp = name
        try:
            os.chmod(tmp, final.stat().st_mode & 0o7777)     # --overwrite: the replaced file's mode
        except FileNotFoundError:
            pass
        yield tmp
        os.replace(tmp, final)
    except BaseException:
        if tmp is not None:
            tmp.unlink(missing_ok=True)
        raise
