"""The packages' dependency rules, tested rather than hoped for (docs/architecture.md).

* ``foveatrack`` runs on real hardware: no module of it outside ``foveatrack.cli`` (the composition
  root, which reaches into ``sim`` lazily inside its commands) may load a ``sim`` module.
* ``gimbal`` is the bottom layer: it loads neither ``sim`` nor ``foveatrack``.

Each module is imported in a fresh interpreter (one per package, modules imported one by one, the
loaded set checked after each) so that one module's imports cannot hide another's.
"""

import json
import pkgutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

CHECK = r"""
import importlib, json, sys
mods, forbidden = json.loads(sys.argv[1]), tuple(json.loads(sys.argv[2]))
bad = {}
for m in mods:
    importlib.import_module(m)
    loaded = [n for n in sys.modules if n.split(".")[0] in forbidden]
    if loaded:
        bad[m] = sorted(loaded)
        break
print(json.dumps(bad))
"""


def _modules(package: str, skip: tuple[str, ...] = ()) -> list[str]:
    root = ROOT / package
    names = [package]
    for info in pkgutil.walk_packages([str(root)], prefix=f"{package}."):
        if not info.name.startswith(skip) and not info.name.endswith(".__main__"):   # __main__ runs the CLI
            names.append(info.name)
    return sorted(names)


@pytest.mark.parametrize("package, forbidden, skip", [
    ("foveatrack", ["sim"], ("foveatrack.cli",)),
    ("gimbal", ["sim", "foveatrack"], ()),
])
def test_a_package_never_loads_what_it_must_not(package, forbidden, skip):
    mods = _modules(package, skip)
    assert len(mods) > 5
    out = subprocess.run([sys.executable, "-c", CHECK, json.dumps(mods), json.dumps(forbidden)], cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert json.loads(out.stdout) == {}, f"{package} loaded {forbidden}: {out.stdout}"


def test_the_check_itself_catches_a_forbidden_import(tmp_path):
    # a module of a package that imports sim is reported
    pkg = tmp_path / "fakepkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "bad.py").write_text("import sim.effects\n")
    env_path = f"{tmp_path}:{ROOT}"
    out = subprocess.run([sys.executable, "-c", CHECK, json.dumps(["fakepkg", "fakepkg.bad"]), json.dumps(["sim"])],
                         cwd=ROOT, capture_output=True, text=True, timeout=300, env={"PYTHONPATH": env_path, "PATH": ""})
    got = json.loads(out.stdout)
    assert set(got) == {"fakepkg.bad"} and {"sim", "sim.effects"} <= set(got["fakepkg.bad"]), got   # and what sim.effects imports


def test_test_files_have_unique_basenames():
    # pytest imports test modules by basename (no __init__.py in the folders): two files of one name
    # stop the whole suite at collection ("import file mismatch"), which two merges did here
    names = {}
    for p in (ROOT / "tests").rglob("test_*.py"):
        names.setdefault(p.name, []).append(str(p.relative_to(ROOT)))
    assert not {n: ps for n, ps in names.items() if len(ps) > 1}
