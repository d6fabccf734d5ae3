"""Where the numba kernels are cached, chosen before any of them is defined.

The kernels are compiled once and cached (``cache=True``).  numba puts the cache next to the sources
(``__pycache__``), or, where that cannot be written (an install into a read-only or system-wide
site-packages), in the user's cache directory (``$XDG_CACHE_HOME/numba``, by default
``~/.cache/numba``).  Where neither can be written -- a service user without a home, a read-only
install run with ``HOME=/nonexistent`` -- numba raised ``RuntimeError: cannot cache function
'...': no locator available`` while the kernels' modules were imported: every command that runs a
kernel ended in that traceback.

:func:`choose` is called by the CLI before any command runs: in that case it points numba at a
directory of this user's own under the system's temporary directory (``NUMBA_CACHE_DIR``, which the
compile processes inherit) and says so on stderr; the run compiles there (about a minute the first
time) and later runs load it, as long as the temporary directory keeps it.  Where that directory's
fixed name is taken by one this user may not trust (another user's, a link, one anybody may write),
the run gets a new directory of its own (``mkdtemp``): that cache is this run's alone, every run
compiles the kernels again, and the messages say so and how to keep them (set ``NUMBA_CACHE_DIR`` to
a directory of this user's).  A ``NUMBA_CACHE_DIR`` the user set is left as it is.
"""

from __future__ import annotations

import os
import stat
import sys
import tempfile
from pathlib import Path

from foveatrack.errors import UserError

#: the directory whose ``__pycache__`` numba caches the package's kernels in (foveatrack/)
SOURCES = Path(__file__).resolve().parents[1]
#: the name prefix of a cache directory made for one run alone (the fixed name was not this user's):
#: what tells the messages, in this process and the compile processes (``NUMBA_CACHE_DIR``), that no
#: later run will load it
RUN_OWN_PREFIX = "foveatrack-numba-cache-run-"


def _writable(directory: Path) -> bool:
    """Whether ``directory`` can be written, or made where it does not exist yet (as numba makes it)."""
    d = directory
    while not d.exists():
        if d.parent == d:
            return False
        d = d.parent
    return d.is_dir() and os.access(d, os.W_OK | os.X_OK)


def user_cache_dir() -> Path:
    """numba's user-wide cache directory on this system (its ``AppDirs('numba').user_cache_dir`` on
    Linux, without importing numba for it)."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache")
    return Path(base) / "numba"


def _own_private_dir(path: Path) -> bool:
    """``path`` made if missing, and then a directory of this user's alone (not a link, nobody else
    may write it: numba's cache files are loaded as code)."""
    try:
        path.mkdir(mode=0o700, exist_ok=True)
        st = os.lstat(path)
    except OSError:
        return False
    return (stat.S_ISDIR(st.st_mode) and st.st_uid == os.geteuid() and not st.st_mode & 0o022
            and os.access(path, os.W_OK | os.X_OK))


def choose() -> str | None:
    """Set ``NUMBA_CACHE_DIR`` where numba would find no cache directory it can write; returns the
    note to print (None: numba's own choice stands).  UserError where no directory can be written."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return None
    in_tree = SOURCES / "__pycache__"
    user_wide = user_cache_dir()
    if _writable(in_tree) or _writable(user_wide):
        return None
    cache = Path(tempfile.gettempdir()) / f"foveatrack-numba-cache-{os.geteuid()}"
    if not _own_private_dir(cache):
        try:        # another user's (or a link) at that name: a directory for this run alone
            cache = Path(tempfile.mkdtemp(prefix=RUN_OWN_PREFIX))
        except OSError as exc:
            raise UserError(f"the numba kernels cannot be cached: neither {in_tree} nor {user_wide} nor the "
                            f"temporary directory can be written ({exc.strerror or exc}); set NUMBA_CACHE_DIR "
                            "to a directory this user can write") from None
    os.environ["NUMBA_CACHE_DIR"] = str(cache)
    if "numba" in sys.modules:      # numba read its configuration at its import
        sys.modules["numba"].config.CACHE_DIR = str(cache)
    where = (f"they are cached in {cache} instead, compiled there on the first run (about a minute); set "
             "NUMBA_CACHE_DIR to keep them elsewhere") if not _run_own(cache) else (
             f"and {cache.parent / f'foveatrack-numba-cache-{os.geteuid()}'} is not this user's alone: they are "
             f"cached in {cache}, this run's own, and compiled again at every run (about a minute); set "
             "NUMBA_CACHE_DIR to a directory this user may write to keep them")
    return (f"foveatrack: note: the numba kernels cannot be cached next to the sources ({in_tree}) nor in "
            f"{user_wide} (neither can be written by this user): {where}")


def _run_own(cache) -> bool:
    """Whether ``cache`` is a directory :func:`choose` made for one run alone."""
    return Path(cache).name.startswith(RUN_OWN_PREFIX)


def place() -> str:
    """Where the kernels are cached, for the messages that say it ("next to the sources", or "in DIR")."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return f"in {os.environ['NUMBA_CACHE_DIR']}"
    if _writable(SOURCES / "__pycache__"):
        return "next to the sources"
    return f"in {user_cache_dir()}"


def cached_text() -> str:
    """Where the kernels were cached and whether later runs load them, for the messages after a
    compile: "cached next to the sources; later runs load them", or for a cache of this run's own
    (:func:`choose`'s ``mkdtemp``) that no later run will find, and what to do about it."""
    own = os.environ.get("NUMBA_CACHE_DIR")
    if own and _run_own(own):
        return (f"cached in {own}, this run's own: every run compiles them again; set NUMBA_CACHE_DIR to a "
                "directory this user may write to keep them")
    return f"cached {place()}; later runs load them"
