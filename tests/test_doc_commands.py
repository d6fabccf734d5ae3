"""Every command the README and the docs show runs as written, from the quick start's environment.

The commands are taken from the fenced code blocks of ``README.md`` and ``docs/*.md``. Each one is held
to what can be checked without running it for minutes:

* a ``foveatrack`` command is parsed by the real CLI parser (an unknown option, a missing argument or a
  wrong choice fails), or, for a usage synopsis with ``[--optional]`` parts, every option it names must
  be one its subcommand has;
* a ``python scripts/X.py`` command names a script that exists and options its ``--help`` lists;
* every repository path it names (``scenes/...``, ``examples/...``, ``tests/...``) exists;
* the quick ones (``QUICK`` below) are run for real, as a user would, in a scratch directory.

The environment is the one the quick start leaves (``. .venv/bin/activate``): the test runs the
commands with this interpreter's ``bin`` first on ``PATH``.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from functools import cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
SHELL_LANGS = {"", "sh", "bash", "console", "shell"}
STARTS = ("foveatrack", "python ", "python3 ", "pytest", ".venv/bin/", ". .venv/", "HYPOTHESIS_PROFILE=")
REPO_DIRS = ("scenes/", "examples/", "scripts/", "tests/", "docs/")

# Commands quick enough to run for real (seconds each, no devices); every one must appear in a doc.
QUICK = (
    "foveatrack gimbal curves --plot curves.png --unit-seeds 0 1",
    "foveatrack lidar info horizon",
)


def _doc_commands() -> list[tuple[str, str]]:
    """(where, command) for every shell command line in a fenced block of the README and the docs."""
    found = []
    for path in DOCS:
        text = path.read_text()
        for block in re.finditer(r"```([a-z]*)\n(.*?)```", text, re.S):
            if block.group(1) not in SHELL_LANGS:
                continue
            joined = block.group(2).replace("\\\n", " ")      # continuation lines
            for line in joined.splitlines():
                line = line.strip()
                if not line.startswith(STARTS) or re.match(r"foveatrack \d", line):   # or a version banner
                    continue
                line = re.split(r"\s+#\s", line, maxsplit=1)[0].rstrip(" &")   # comment, background
                for part in line.split("&&"):
                    found.append((path.relative_to(ROOT).as_posix(), part.strip()))
    return found


COMMANDS = _doc_commands()


def _argv(command: str) -> list[str]:
    # a $(...) substitution stands for one argument the user's shell would fill in
    return shlex.split(re.sub(r'"?\$\(.*?\)"?', "SUBSTITUTED", command))


@cache
def _parser():
    from foveatrack.cli import build_parser
    return build_parser()


def _subparser(argv: list[str]):
    """The deepest subparser the words of argv lead to, and the words it takes."""
    import argparse
    parser, i = _parser(), 0
    while True:
        sub = next((a for a in parser._actions if isinstance(a, argparse._SubParsersAction)), None)
        if sub is None or i >= len(argv) or argv[i] not in sub.choices:
            return parser, argv[i:]
        parser, i = sub.choices[argv[i]], i + 1


def test_the_docs_show_commands_to_check():
    assert len(COMMANDS) > 25
    assert sum(c.startswith("foveatrack") for _, c in COMMANDS) > 15


@pytest.mark.parametrize("where, command", COMMANDS, ids=[f"{w}:{c[:60]}" for w, c in COMMANDS])
def test_a_documented_command_is_one_that_runs(where, command):
    argv = _argv(command)
    while argv and "=" in argv[0] and not argv[0].startswith("-"):   # VAR=value prefixes
        argv = argv[1:]
    if argv[:1] == ["."]:                                            # `. .venv/bin/activate`
        assert argv[1] == ".venv/bin/activate", command
        assert (Path(sys.prefix) / "bin" / "activate").exists() or sys.prefix == sys.base_prefix
        return
    if argv[0].startswith(".venv/bin/"):
        argv[0] = argv[0].removeprefix(".venv/bin/")
    for word in argv:
        if word.startswith(REPO_DIRS) and not any(ch in word for ch in "*[]{}"):
            first = word.split(",")[0]
            if Path(first).suffix:   # a file the command reads (outputs under docs/ are written, not read)
                if first.startswith("docs/") and not (ROOT / first).exists():
                    continue
                assert (ROOT / first).exists(), f"{where}: {command!r} names {first}, which does not exist"
    if argv[0] == "foveatrack":
        parser, rest = _subparser(argv[1:])
        if any("[" in w for w in argv) or any(w.isupper() and len(w) > 1 for w in rest if not w.startswith("-")):
            # a synopsis: every option it names must exist
            known = {s for a in parser._actions for s in a.option_strings}
            for word in re.findall(r"--[a-z][a-z0-9-]*", " ".join(rest)):
                assert word in known, f"{where}: {command!r}: {word} is not an option of it"
        else:
            try:
                parser.parse_args(rest)
            except SystemExit as exc:
                pytest.fail(f"{where}: {command!r} does not parse (exit {exc.code})")
    elif argv[0] in ("python", "python3") and argv[1] not in ("-c", "-m"):
        script = ROOT / argv[1]
        assert script.exists(), f"{where}: {command!r}: no {argv[1]}"
        opts = re.findall(r"--[a-z][a-z0-9-]*", " ".join(argv[2:]))
        if opts:
            out = subprocess.run([sys.executable, str(script), "--help"], cwd=ROOT, capture_output=True,
                                 text=True, timeout=120)
            assert out.returncode == 0, out.stderr[-1000:]
            for opt in opts:
                assert opt in out.stdout, f"{where}: {command!r}: {argv[1]} has no option {opt}"
    elif argv[0] == "python" and argv[1] == "-c":
        compile(argv[2], "<doc>", "exec")
    elif argv[0] == "pytest" or argv[1:3] == ["-m", "pytest"]:
        for word in argv:
            if word.startswith("tests"):
                assert (ROOT / word.split("::")[0]).exists(), f"{where}: {command!r}: no {word}"


@pytest.mark.parametrize("command", QUICK)
def test_a_quick_documented_command_runs_as_written(command, tmp_path):
    assert any(c == command for _, c in COMMANDS), f"{command!r} is no longer in the docs"
    for name in ("scenes", "examples"):
        (tmp_path / name).symlink_to(ROOT / name)
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}")
    out = subprocess.run(command, shell=True, cwd=tmp_path, env=env, capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, f"{command!r} exited {out.returncode}: {out.stderr[-2000:]}"
