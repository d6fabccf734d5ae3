"""The code's shape in four counts, read from the sources (issue 25's before/after figures).

* frame loops written by hand: functions (outside the one step, the gate and controller classes) that
  run a controller's ``process(frame, send_t)`` or the gate's ``decide`` themselves;
* modules over 400 lines, functions over 80 lines (of ``foveatrack``, ``sim``, ``gimbal``);
* import circles between units (the units of ``tests/test_dependency_rules.py``: the packages, each
  subpackage of ``foveatrack``, its core) and arrows running up (imports its layer table does not allow,
  at any depth, known exceptions included).

Usage: python scripts/code_shape.py [TREE] [--list]   (TREE: a source tree, default this one)
"""

from __future__ import annotations

import argparse
import ast
import importlib.util
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]
SCANNED = ("foveatrack", "sim", "scripts")
SIZED = ("foveatrack", "sim", "gimbal")
MODULE_LINES, FUNCTION_LINES = 400, 80


def _py(root: Path, tops) -> list[Path]:
    return sorted(p for t in tops for p in (root / t).rglob("*.py") if "__pycache__" not in p.parts)


def frame_loops(root: Path) -> list[str]:
    """Functions that call a controller's ``process(frame, send_t)`` or a gate's ``decide`` themselves."""
    out = []
    for p in _py(root, SCANNED):
        rel = p.relative_to(root).as_posix()
        if rel in ("foveatrack/gate.py",):
            continue
        tree = ast.parse(p.read_text(encoding="utf-8"))
        skip = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.ClassDef):
                names = {n.name for n in node.body if isinstance(n, ast.FunctionDef)}
                if {"process", "command_sent"} <= names or node.name == "FrameStep":
                    skip.update(id(n) for n in ast.walk(node))

        def hits(fn) -> bool:
            for n in ast.walk(fn):
                if isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute) and id(n) not in skip:
                    a = n.func.attr
                    two = len(n.args) >= 2 or any(k.arg == "send_t_s" for k in n.keywords)
                    if a == "decide" or (a == "process" and two):
                        return True
            return False

        # the innermost function holding such a call counts once
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and id(node) not in skip and hits(node):
                inner = [n for n in ast.walk(node) if n is not node and isinstance(n, (ast.FunctionDef,
                                                                                       ast.AsyncFunctionDef))
                         and hits(n)]
                if not inner:
                    out.append(f"{rel}:{node.lineno} {node.name}")
    return out


def long_modules(root: Path) -> list[str]:
    out = []
    for p in _py(root, SIZED):
        n = len(p.read_text(encoding="utf-8").splitlines())
        if n > MODULE_LINES:
            out.append(f"{p.relative_to(root).as_posix()} {n}")
    return out


def long_functions(root: Path) -> list[str]:
    out = []
    for p in _py(root, SIZED):
        for node in ast.walk(ast.parse(p.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > FUNCTION_LINES:
                    out.append(f"{p.relative_to(root).as_posix()}:{node.lineno} {node.name} {n}")
    return out


def _rules(root: Path):
    """The dependency test's table and helpers, loaded from the tree (or this one's if it has none)."""
    path = root / "tests" / "test_dependency_rules.py"
    if not path.exists():
        path = HERE / "tests" / "test_dependency_rules.py"
    spec = importlib.util.spec_from_file_location("_rules", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    mod.ROOT = root
    return mod


def unit_arrows(root: Path) -> tuple[list[str], list[str]]:
    """(circles between units, arrows against the layer table)."""
    r = _rules(root)
    edges: dict[str, set[str]] = {}
    up = []
    for path in sorted(p for pkg in r.PACKAGES for p in (root / pkg).rglob("*.py")):
        mod = r.module_name(path)
        src = r.unit_of(mod)
        for target, line in r.imports_of(path):
            if target.split(".")[0] not in r.PACKAGES:
                continue
            dst = r.unit_of(target)
            if dst == src:
                continue
            edges.setdefault(src, set()).add(dst)
            if dst not in r.MAY_IMPORT.get(src, set()):
                up.append(f"{path.relative_to(root).as_posix()}:{line} {src} -> {dst}")
    # circles: strongly connected sets of units (Tarjan)
    index, low, stack, on, comps = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in edges.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                comps.append(" <-> ".join(sorted(comp)))

    for v in sorted(set(edges) | {w for ws in edges.values() for w in ws}):
        if v not in index:
            visit(v)
    return comps, up


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("tree", nargs="?", type=Path, default=HERE)
    ap.add_argument("--list", action="store_true", help="name every item counted")
    args = ap.parse_args()
    root = args.tree.resolve()
    circles, up = unit_arrows(root)
    rows = [("frame loops written by hand", frame_loops(root)),
            (f"modules over {MODULE_LINES} lines", long_modules(root)),
            (f"functions over {FUNCTION_LINES} lines", long_functions(root)),
            ("import circles between units", circles), ("arrows running up (against the layer table)", up)]
    print(f"tree: {root}")
    for name, items in rows:
        print(f"{len(items):4d}  {name}")
        if args.list:
            for it in items:
                print(f"        {it}")


if __name__ == "__main__":
    sys.exit(main())
