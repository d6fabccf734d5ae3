"""The packages' dependency rules, checked on the source (docs/architecture.md).

Every ``import`` and ``from ... import`` statement of ``gimbal``, ``foveatrack`` and ``sim`` -- at
module level or inside a function (a lazy import loads the module just the same, only later) -- is read
by AST and its target checked against :data:`MAY_IMPORT`, a table of *units*: the three packages, each
subpackage of ``foveatrack`` (``foveatrack.recording``, ``foveatrack.livox``, ...), and the core of
``foveatrack`` (its top-level modules: frames, detection, control, tracker, gate, ...).  A unit may
import itself and what its row lists, nothing else; so the direction runs

    gimbal  <-  foveatrack (core)  <-  recording  <-  livox  <-  live_devices  <-  calibration, imu_calib,
    replay, daemon  <-  sim  <-  cli;   foveatrack (core)  <-  sources  <-  openloop (and recording)

and no two units import each other (a cycle is two rows naming each other; the test says so).  Known
exceptions, each with why it stays, are in :data:`KNOWN_EXCEPTIONS` (module -> target unit), reported
by the test if they disappear so the table shrinks with the code.

What the AST cannot see: an ``importlib.import_module`` of a computed name (the CLI registers its
commands that way, inside ``foveatrack.cli`` where everything is allowed anyway).
"""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("gimbal", "foveatrack", "sim")

# unit -> the other units it may import (a unit may always import itself)
_CORE = "foveatrack"
MAY_IMPORT: dict[str, set[str]] = {
    "gimbal": set(),
    _CORE: {"gimbal"},
    "foveatrack.recording": {_CORE, "gimbal"},
    "foveatrack.livox": {_CORE, "foveatrack.recording"},
    # opens the devices for the daemon and the live calibrations (a module of the core by place, a
    # layer of its own by what it imports)
    "foveatrack.live_devices": {_CORE, "foveatrack.livox", "gimbal"},
    "foveatrack.calibration": {_CORE, "foveatrack.live_devices"},
    "foveatrack.imu_calib": {_CORE, "foveatrack.live_devices"},
    # replay and the daemon run the multi-object tracker where a recording or a config asks for it
    "foveatrack.replay": {_CORE, "foveatrack.recording", "foveatrack.livox", "foveatrack.sky", "gimbal"},
    # frames from other programs' recordings (ROS bags, PCD, numpy folders), and the fixed sensor's
    # open-loop tracker that consumes them and writes our recording
    "foveatrack.sources": {_CORE},
    "foveatrack.openloop": {_CORE, "foveatrack.sources", "foveatrack.recording"},
    # many objects seen from the moving head: the open-loop tracker's background and clustering,
    # used on world coordinates
    "foveatrack.sky": {_CORE, "foveatrack.openloop"},
    "foveatrack.daemon": {_CORE, "foveatrack.recording", "foveatrack.livox", "foveatrack.live_devices", "foveatrack.sky",
                          "gimbal"},
    "sim": {_CORE, "foveatrack.sky", "foveatrack.recording", "foveatrack.livox", "foveatrack.live_devices", "foveatrack.calibration",
            "foveatrack.imu_calib", "foveatrack.replay", "foveatrack.daemon", "gimbal"},
    # the composition root: everything, sim lazily inside its commands
    "foveatrack.cli": {_CORE, "foveatrack.recording", "foveatrack.livox", "foveatrack.live_devices",
                       "foveatrack.calibration", "foveatrack.imu_calib", "foveatrack.replay", "foveatrack.daemon",
                       "foveatrack.sources", "foveatrack.openloop", "foveatrack.sky", "gimbal", "sim"},
    "foveatrack.__main__": {"foveatrack.cli"},
}

# (importing module, imported unit): breaks of the table the code still has, each with its reason
KNOWN_EXCEPTIONS: set[tuple[str, str]] = set()
# (none left: the live calibration read the daemon's device configuration from foveatrack.daemon
# until it moved below both, to foveatrack/device_config.py)


def unit_of(module: str) -> str:
    """The unit a dotted module name belongs to (see the module docstring)."""
    parts = module.split(".")
    if parts[0] != "foveatrack":
        return parts[0]
    if len(parts) == 1:
        return _CORE
    if (ROOT / "foveatrack" / parts[1]).is_dir() or parts[1] in ("live_devices", "__main__"):
        return f"foveatrack.{parts[1]}"
    return _CORE


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imports_of(path: Path, text: str | None = None) -> list[tuple[str, int]]:
    """Every module a file imports (absolute dotted names, relative ones resolved), with the line; at
    any depth (a function's lazy import too).  ``from a import b`` counts as ``a.b`` (``b`` may be a
    submodule) -- its unit is ``a``'s unless ``a`` is a package root."""
    tree = ast.parse(path.read_text() if text is None else text, str(path))
    mod = module_name(path)
    package = mod.split(".") if path.name == "__init__.py" else mod.split(".")[:-1]
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(a.name, node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package[: len(package) - (node.level - 1)]
                base = ".".join(up + ([base] if base else []))
            out += [(f"{base}.{a.name}" if base else a.name, node.lineno) for a in node.names]
    return out


def violations(files, text: str | None = None) -> list[str]:
    """Imports against the table, one line each (``text``: the source of the one file given, for tests)."""
    bad = []
    for path in files:
        mod = module_name(path)
        src = unit_of(mod)
        for target, line in imports_of(path, text):
            if target.split(".")[0] not in PACKAGES:
                continue        # the standard library and third-party packages
            dst = unit_of(target)
            if dst == src or dst in MAY_IMPORT[src] or (mod, dst) in KNOWN_EXCEPTIONS:
                continue
            bad.append(f"{path.relative_to(ROOT)}:{line}: {mod} ({src}) imports {target} ({dst})")
    return bad


def _files():
    return sorted(p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py"))


def test_every_import_statement_follows_the_layer_table():
    files = _files()
    assert len(files) > 100
    units = {unit_of(module_name(p)) for p in files}
    assert units <= set(MAY_IMPORT), f"units without a row in MAY_IMPORT: {sorted(units - set(MAY_IMPORT))}"
    bad = violations(files)
    assert not bad, "imports against the layer table (docs/architecture.md):\n" + "\n".join(bad)


def test_the_layer_table_has_no_cycle():
    # a unit may not reach itself through the table (the livox <-> recording cycle was one)
    def reach(u, seen):
        for v in MAY_IMPORT[u]:
            if v not in seen:
                seen.add(v)
                reach(v, seen)
        return seen
    assert not [u for u in MAY_IMPORT if u in reach(u, set())]


def test_known_exceptions_are_still_needed():
    # an exception the code no longer needs is removed from the table, so that it cannot come back
    used = set()
    for path in _files():
        mod = module_name(path)
        for target, _ in imports_of(path):
            if target.split(".")[0] in PACKAGES and (mod, unit_of(target)) in KNOWN_EXCEPTIONS:
                used.add((mod, unit_of(target)))
    assert used == KNOWN_EXCEPTIONS, KNOWN_EXCEPTIONS - used


@pytest.mark.parametrize("code", ["def f():\n    from sim import effects\n", "import sim.effects\n",
                                  "class A:\n    def f(self):\n        import foveatrack.cli\n"])
def test_the_check_sees_lazy_and_eager_imports(code):
    # a module of the core that imports sim (or the CLI), at any depth, is reported
    bad = violations([ROOT / "foveatrack" / "_planted.py"], code)
    assert len(bad) == 1 and "foveatrack._planted (foveatrack) imports" in bad[0], bad


def test_relative_imports_resolve_to_their_package():
    path = ROOT / "foveatrack" / "recording" / "_planted.py"
    assert imports_of(path, "from .. import tracker\nfrom ..livox import protocol\n") == [
        ("foveatrack.tracker", 1), ("foveatrack.livox.protocol", 2)]
    # recording may import the core, not livox (livox reads recordings: lvx_export)
    bad = violations([path], "from .. import tracker\nfrom ..livox import protocol\n")
    assert len(bad) == 1 and "imports foveatrack.livox.protocol (foveatrack.livox)" in bad[0], bad


def test_test_files_have_unique_basenames():
    # pytest imports test modules by basename (no __init__.py in the folders): two files of one name
    # stop the whole suite at collection ("import file mismatch"), which two merges did here
    names = {}
    for p in (ROOT / "tests").rglob("test_*.py"):
        names.setdefault(p.name, []).append(str(p.relative_to(ROOT)))
    assert not {n: ps for n, ps in names.items() if len(ps) > 1}
