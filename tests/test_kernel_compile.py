"""A first run compiles the numba kernels in two processes at once (foveatrack.cli.kernel_compile):
the demo on an empty cache says what it compiles, its own process then compiles nothing (every
kernel its run and its scan figures call was compiled by the two processes and loads from the
cache), and the two processes leave a consistent cache (each index entry names a data file of its
own signature; numba rewrites a whole index per signature, so two processes compiling one function
could break that)."""

import os
import pickle
import subprocess
import sys
from pathlib import Path

import pytest

from foveatrack.cli import kernel_compile

ROOT = Path(__file__).resolve().parents[1]

# The demo with every numba compile in its own process recorded (kernels loaded from the cache are not compiles).
DEMO_COUNTING_COMPILES = """
import sys
from numba.core import event

compiled = []


class Compiles(event.Listener):
    def on_start(self, ev):
        pass

    def on_end(self, ev):
        f = ev.data["dispatcher"].py_func
        compiled.append(f"{f.__module__}.{f.__qualname__}")


event.register("numba:compile", Compiles())
from foveatrack.cli import main

code = main(["demo", "--out", sys.argv[1]] if len(sys.argv) == 2 else sys.argv[2:])
print("COMPILED", sorted(set(compiled)))
sys.exit(code)
"""


def _index_entries(cache_dir: Path):
    """(index file, signature in the index, signature in the data file it names) of every entry."""
    for index in sorted(cache_dir.rglob("*.nbi")):
        with open(index, "rb") as fh:
            pickle.load(fh)                       # numba's version
            _stamp, overloads = pickle.loads(fh.read())
        for key, data_name in overloads.items():
            data = pickle.loads((index.parent / data_name).read_bytes())
            yield index.name, tuple(key[0]), tuple(data[3].args)


@pytest.mark.slow
def test_a_first_demo_compiles_in_two_processes_and_its_first_frame_compiles_nothing(tmp_path):
    cache = tmp_path / "numba-cache"
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    run = subprocess.run([sys.executable, "-c", DEMO_COUNTING_COMPILES, str(tmp_path / "demo")], cwd=ROOT, env=env,
                         capture_output=True, text=True, timeout=1800)
    assert run.returncode == 0, run.stderr[-3000:]
    err = run.stderr
    # announced with what it is doing, group by group
    assert "compiling the numba kernels" in err and "2 groups in 2 processes" in err
    for i, group in enumerate(kernel_compile.GROUPS):
        assert f"[{i + 1}/2] {group.name} ..." in err
        assert f"[{i + 1}/2] {group.name}: ready after " in err
    assert "failed" not in err
    compiled = [line for line in run.stdout.splitlines() if line.startswith("COMPILED")]
    assert compiled == ["COMPILED []"], compiled      # the run and the scan figures loaded every kernel
    assert "296 with a detection" in run.stdout       # the demo's result, as documented (docs/first-run.md)

    entries = list(_index_entries(cache))
    names = {name.split("-")[0] for name, _, _ in entries}
    for needed in ("kernels.scan_exact_kernel", "kernels.cast_static_kernel", "sensor_kernels.assemble_returns_kernel",
                   "kernels.box_median_kernel", "pack_kernels.pack_grid_kernel", "kernels.trace_paraxial_kernel"):
        assert needed in names
    mismatched = [(name, key, data) for name, key, data in entries if key != data]
    assert not mismatched
    # and the next run finds the cache warm: no compile processes again
    warm = subprocess.run([sys.executable, "-c", "from foveatrack.cli import kernel_compile as k; print(k.cache_is_cold())"],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert warm.stdout.strip() == "False", warm.stderr


@pytest.mark.slow
def test_a_first_sky_run_compiles_in_two_processes_and_its_run_compiles_nothing(tmp_path):
    # A sky scene's run calls the sky tracker's kernels from its first frame, and at its warm-up's end
    # (compile_sky_kernels): both compile processes once failed on a fresh install (a kernel of no group
    # called foveatrack.kernels' inline helper, run as Python in the other group's process; a kernel run
    # as Python summed uint8s and wrapped), and the run compiled everything again in its first frames
    cache = tmp_path / "numba-cache"
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    run = subprocess.run([sys.executable, "-c", DEMO_COUNTING_COMPILES, "-", "simulate",
                          "scenes/swarm-of-five.toml", "--out", str(tmp_path / "swarm"), "--duration", "2"],
                         cwd=ROOT, env=env, capture_output=True, text=True, timeout=1800)
    assert run.returncode == 0, run.stderr[-3000:]
    assert "2 groups in 2 processes" in run.stderr
    assert "failed" not in run.stderr, run.stderr[-3000:]
    compiled = [line for line in run.stdout.splitlines() if line.startswith("COMPILED")]
    assert compiled == ["COMPILED []"], compiled
    assert not [e for e in _index_entries(cache) if e[1] != e[2]]


def test_every_kernel_module_is_in_one_group():
    """A module with numba kernels outside the groups is compiled by both processes at once, and its
    kernels that call another module's inline helpers fail in the process that runs those as Python."""
    grouped = {m for g in kernel_compile.GROUPS for m in g.modules}
    with_kernels = set()
    for top in ("foveatrack", "sim", "gimbal"):
        for path in (ROOT / top).rglob("*.py"):
            if "@njit" in path.read_text():
                with_kernels.add(".".join(path.relative_to(ROOT).with_suffix("").parts))
    assert with_kernels and with_kernels <= grouped, sorted(with_kernels - grouped)


def test_a_compile_process_runs_the_other_groups_kernels_as_python(tmp_path):
    """The swap a compile process makes: the other group's dispatchers become their Python functions."""
    code = ("from foveatrack.cli import kernel_compile as kc\n"
            "kc.run_kernels_as_python(kc.GROUPS[1].modules)\n"
            "import sim.world.kernels as wk, sim.sensor_kernels as sk, sim.scan.kernels as sc\n"
            "from numba.core.dispatcher import Dispatcher\n"
            "assert not isinstance(wk.cast_static_kernel, Dispatcher) and callable(wk.cast_static_kernel)\n"
            "assert not isinstance(sk.exp_portable, Dispatcher)\n"
            "assert isinstance(sc.scan_exact_kernel, Dispatcher)\n")
    run = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300,
                         env=dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path)))
    assert run.returncode == 0, run.stderr


def test_the_groups_share_no_module():
    modules = [m for g in kernel_compile.GROUPS for m in g.modules]
    assert len(modules) == len(set(modules))
    for g in kernel_compile.GROUPS:
        assert all(s.split(":")[0] in g.modules for s in g.sentinels)
