"""An output file that appears under its name only when it is whole.

:func:`written_whole` gives a temporary file beside the output to write, and renames it onto the
output's name (``os.replace``, atomic on one file system) only when the writing ended without an
exception; an exception -- KeyboardInterrupt too -- removes it.  A Ctrl-C during an export left a
CSV with 917 505 of its 1 251 727 lines, and an NPZ that would not decompress, under the names a
finished export has: ``--overwrite`` was then asked for as if it were one.  With ``fsync`` the file
and then its directory are synced to the disk, so a power loss leaves the old file or the new one
(``recover`` rewrites a recording in place this way).  A process killed inside the block cannot
remove its temporary: :func:`leftovers` names those for a later run to clear.  A core module: the
recording layer, the Livox layer and the daemon's ``recover`` all write through it.
"""

from __future__ import annotations

import glob
import os
import re
import secrets
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator


class RenameRefused(PermissionError):
    """The rename of the whole temporary onto the output was refused (a sticky directory: another user's
    file), and only that: a PermissionError raised while the block read or wrote is not one."""


def temporary_name(final: Path) -> Path:
    """A fresh name for a temporary of ``final`` (already resolved), beside it: ``.NAME.<8 hex digits>.tmp``,
    what :func:`leftovers` finds.  The one place that pattern is made (``recover``'s probe takes it too)."""
    return final.with_name(f".{final.name}.{secrets.token_hex(4)}.tmp")


@contextmanager
def written_whole(path: str | os.PathLike, fsync: bool = False) -> Iterator[Path]:
    """The path of an empty temporary file in ``path``'s directory (a hidden name, ``.NAME.<8 hex digits>.tmp``),
    for the caller to write (open it with "w"/"wb", or let a writer that creates its file itself
    replace it); it gets the mode of the file it replaces (else the one a new file gets under the
    umask), moved onto ``path`` when the block ends, removed if it raises.  ``fsync``: the file is
    synced before the rename and the directory after it (best-effort: the file is replaced by then).  A symlink at ``path`` is written through:
    its target is replaced."""
    final = Path(os.path.realpath(path))
    tmp = name = None      # name: the temporary being made (a refused creation names it, tmp still None)
    renaming = False
    try:
        while tmp is None:
            name = temporary_name(final)
            try:
                os.close(os.open(name, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
            except FileExistsError:
                continue
            tmp = name
        try:
            mode = final.stat().st_mode & 0o7777     # --overwrite: the replaced file's mode
        except FileNotFoundError:
            mode = None
        if mode is not None:
            os.chmod(tmp, mode)         # before the writing: a private file's contents stay private
        yield tmp
        if mode is not None:
            os.chmod(tmp, mode)         # again: a writer may have made the file anew under the umask
        if fsync:
            _fsync(tmp, os.O_RDONLY)
        renaming = True
        try:
            os.replace(tmp, final)
        except PermissionError as exc:
            raise RenameRefused(exc.errno, exc.strerror, str(path)) from None
    except BaseException as exc:
        if tmp is not None:
            tmp.unlink(missing_ok=True)
        if renaming:
            # the rename's own error names both files: a temporary gone (ENOENT) or another file system
            # (EXDEV) is not the output's to be named by
            raise
        if isinstance(exc, OSError) and exc.errno is not None and (
                exc.filename is None or str(exc.filename) in (str(tmp), str(name))):
            # a write that failed (a full disk) names no file, or the hidden temporary (its creation refused
            # too: 'export --csv /sys/out.csv' said '/sys/.out.csv.1a2b3c4d.tmp: Permission denied'): the
            # output's own name is the one the user gave (an export on a full disk said only "No space left
            # on device")
            raise type(exc)(exc.errno, exc.strerror, str(path)) from None
        raise
    if fsync:
        # the rename itself, best-effort: the file is replaced by now, whole, and an error here is not a
        # failure to write it (a directory this user may write but not read, 0333, cannot be opened to
        # sync; recover then said "nothing was changed" of a recording it had replaced)
        try:
            _fsync(final.parent, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
        except OSError:
            pass


def leftovers(path: str | os.PathLike) -> list[Path]:
    """The temporaries :func:`written_whole` made for ``path`` that are still there: a process killed
    inside the block (``kill -9``, a power loss) never removed its own.  Whether one is still being
    written by a running process is for the caller to tell."""
    final = Path(os.path.realpath(path))
    own = re.compile(re.escape(f".{final.name}.") + r"[0-9a-f]{8}\.tmp")
    return sorted(p for p in final.parent.glob(glob.escape(f".{final.name}.") + "*.tmp") if own.fullmatch(p.name))


def _fsync(path, flags: int) -> None:
    fd = os.open(path, flags)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
