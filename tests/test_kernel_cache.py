"""Where the numba kernels are cached when this user can write neither next to the sources nor in
the user's cache directory (a read-only install run by a user without a home, e.g. a service):
numba raised "RuntimeError: cannot cache function '...': no locator available" while the kernels'
modules were imported, and every command that runs a kernel ended in that traceback.

Root may write anywhere, so "this user may not write there" is simulated: ``os.access`` says so for
the sources' and the user's cache directories, and in the subprocess numba is told to look only where
``NUMBA_CACHE_DIR`` points (``NUMBA_CACHE_LOCATOR_CLASSES``), which is what it finds for such a user."""

import os
import stat
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from foveatrack.cli import kernel_cache

ROOT = Path(__file__).resolve().parents[1]


def _make_unwritable(tmp_path, monkeypatch):
    """The sources' and the user's cache directories not writable for this user; a temporary
    directory of the test's own.  What choose() sets -- the environment's ``NUMBA_CACHE_DIR`` and the
    imported numba's ``config.CACHE_DIR`` -- is undone with ``monkeypatch``: left set, every kernel
    defined later in the pytest session cached into this test's temporary directory (and, with the
    tests in random order, recompiled there)."""
    import numba

    home_cache = tmp_path / "home" / ".cache"
    (tmp_path / "home").mkdir()
    monkeypatch.setenv("XDG_CACHE_HOME", str(home_cache))
    monkeypatch.setenv("NUMBA_CACHE_DIR", "")
    monkeypatch.delenv("NUMBA_CACHE_DIR")
    monkeypatch.setattr(numba.config, "CACHE_DIR", numba.config.CACHE_DIR)
    monkeypatch.setattr(kernel_cache.tempfile, "tempdir", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    real_access = os.access
    denied = (str(kernel_cache.SOURCES), str(tmp_path / "home"))

    def access(path, mode, *a, **kw):
        if mode & os.W_OK and str(path).startswith(denied):
            return False
        return real_access(path, mode, *a, **kw)

    monkeypatch.setattr(os, "access", access)
    return tmp_path


@pytest.fixture
def unwritable(tmp_path, monkeypatch):
    return _make_unwritable(tmp_path, monkeypatch)


def test_what_choose_sets_is_undone_after_the_test(tmp_path):
    import numba

    before = (os.environ.get("NUMBA_CACHE_DIR"), numba.config.CACHE_DIR)
    mp = pytest.MonkeyPatch()
    try:
        _make_unwritable(tmp_path, mp)
        kernel_cache.choose()
        assert numba.config.CACHE_DIR.startswith(str(tmp_path))      # choose() set it...
    finally:
        mp.undo()
    assert (os.environ.get("NUMBA_CACHE_DIR"), numba.config.CACHE_DIR) == before    # ...and it is undone


def test_no_writable_cache_gets_a_private_one_and_a_note(unwritable, monkeypatch):
    note = kernel_cache.choose()
    cache = unwritable / "tmp" / f"foveatrack-numba-cache-{os.geteuid()}"
    assert os.environ["NUMBA_CACHE_DIR"] == str(cache)
    assert stat.S_IMODE(cache.stat().st_mode) == 0o700
    assert note.startswith("foveatrack: note: the numba kernels cannot be cached next to the sources")
    assert str(cache) in note and "NUMBA_CACHE_DIR" in note
    assert kernel_cache.place() == f"in {cache}"


def test_a_cache_dir_others_may_write_is_never_used(unwritable):
    """numba loads its cache files as code: a directory at the fixed name that another user made,
    or one anybody may write, is passed over for one of this run's own."""
    planted = unwritable / "tmp" / f"foveatrack-numba-cache-{os.geteuid()}"
    planted.mkdir()
    planted.chmod(0o777)
    kernel_cache.choose()
    got = Path(os.environ["NUMBA_CACHE_DIR"])
    assert got != planted and got.parent == unwritable / "tmp" and stat.S_IMODE(got.stat().st_mode) == 0o700


def test_a_cache_of_this_runs_own_is_not_said_to_be_loaded_by_later_runs(unwritable):
    """mkdtemp makes a new directory at every run: "later runs load them" (warmup, the compile) was
    false; the note and the messages say the cache is this run's own and how to keep the kernels."""
    planted = unwritable / "tmp" / f"foveatrack-numba-cache-{os.geteuid()}"
    planted.mkdir()
    planted.chmod(0o777)
    note = kernel_cache.choose()
    got = os.environ["NUMBA_CACHE_DIR"]
    assert f"{planted} is not this user's alone" in note and f"cached in {got}, this run's own" in note, note
    assert "compiled again at every run" in note and "NUMBA_CACHE_DIR to a directory" in note, note
    assert "first run" not in note, note
    said = kernel_cache.cached_text()
    assert "later runs load them" not in said and f"in {got}, this run's own" in said, said
    assert "every run compiles them again" in said and "set NUMBA_CACHE_DIR" in said, said


def test_a_kept_cache_is_said_to_be_loaded_by_later_runs(unwritable):
    kernel_cache.choose()
    cache = unwritable / "tmp" / f"foveatrack-numba-cache-{os.geteuid()}"
    assert kernel_cache.cached_text() == f"cached in {cache}; later runs load them"


def test_numba_s_own_choice_stands_where_it_can_write(tmp_path, monkeypatch):
    monkeypatch.setenv("NUMBA_CACHE_DIR", "")
    monkeypatch.delenv("NUMBA_CACHE_DIR")
    assert kernel_cache.choose() is None and "NUMBA_CACHE_DIR" not in os.environ    # root: next to the sources
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "mine"))
    assert kernel_cache.choose() is None and os.environ["NUMBA_CACHE_DIR"] == str(tmp_path / "mine")


CHECK_SCRIPT = textwrap.dedent(
    """
    import os, sys
    denied = (sys.argv[2], sys.argv[3])
    real_access = os.access
    os.access = lambda p, m, *a, **k: False if m & os.W_OK and str(p).startswith(denied) else real_access(p, m, *a, **k)
    import tempfile
    tempfile.tempdir = sys.argv[4]
    from foveatrack.cli import main
    sys.exit(main(["daemon", "--config", sys.argv[1], "--check"]))
    """
)


def test_a_command_runs_where_no_cache_dir_can_be_written(tmp_path):
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:     # a port nothing answers on
        s.bind(("127.0.0.1", 0))
        silent = s.getsockname()[1]
    cfg = tmp_path / "d.toml"
    cfg.write_text(f'[lidar]\nsensor_ip = "127.0.0.1"\nhost_ip = "127.0.0.1"\ncmd_port = 0\ndata_port = 0\n'
                   f'broadcast_port = false\nsensor_cmd_port = {silent}\n[head]\nport = "loop://"\n'
                   f'[recording]\npath = "{tmp_path}/r-{{time}}.mcap"\n')
    (tmp_path / "tmp").mkdir()
    (tmp_path / "home").mkdir()
    env = dict(os.environ, PYTHONPATH=str(ROOT), XDG_CACHE_HOME=str(tmp_path / "home" / ".cache"),
               NUMBA_CACHE_LOCATOR_CLASSES="UserProvidedCacheLocator")
    env.pop("NUMBA_CACHE_DIR", None)
    r = subprocess.run([sys.executable, "-c", CHECK_SCRIPT, str(cfg), str(kernel_cache.SOURCES),
                        str(tmp_path / "home"), str(tmp_path / "tmp")],
                       capture_output=True, text=True, env=env, timeout=300, cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "no locator available" not in r.stderr and "Traceback" not in r.stderr
    assert "foveatrack: note: the numba kernels cannot be cached next to the sources" in r.stderr
    # numba found its cache there for every kernel the command defined (it found none before)
    assert (tmp_path / "tmp" / f"foveatrack-numba-cache-{os.geteuid()}").is_dir()
