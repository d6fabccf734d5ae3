"""Small helpers to validate user mappings (scene ``[tracker]`` tables, daemon configs).

Every error names *where* the mapping came from, the key, and what is allowed.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

from foveatrack.errors import UserError


def positive_arg(text: str) -> float:
    """argparse type: a finite number > 0."""
    import argparse
    import math

    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (v > 0 and math.isfinite(v)):
        raise argparse.ArgumentTypeError(f"{text!r}: must be a positive number")
    return v


def seed_arg(text: str) -> int:
    """argparse ``type=`` for seeds and unit seeds: an integer >= 0 (numpy's SeedSequence rejects
    negative ones with a traceback deep inside the run)."""
    import argparse

    try:
        v = int(text, 0)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"{text!r}: a seed must be an integer >= 0")
    return v


def check_output_file(path, flag: str) -> None:
    """Fail early, before a long run, if the output file ``path`` (given with ``flag``) cannot be
    written: its directory must exist, and the path must not be a directory."""
    import os
    from pathlib import Path

    p = Path(path)
    parent = p.parent if str(p.parent) else Path(".")
    if p.is_dir():
        raise UserError(f"{flag} {path}: is a directory; give a file name")
    if not parent.is_dir():
        raise UserError(f"{flag} {path}: the directory {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise UserError(f"{flag} {path}: the directory {parent} is not writable")


def check_outputs(outputs, inputs=(), overwrite: bool = False) -> None:
    """A command's output files ``outputs`` ((flag, path) pairs, or (flag, path, suffixes): the name must
    end in one of them; a None path is not asked for), each checked by :func:`check_output_file`, and
    never a file it reads (``inputs``: files, or directories
    whose files it reads), never one another's, and -- unless ``overwrite`` -- never a file that exists:
    what a user already has is not replaced unasked (a track's --csv named one of its own scans
    replaced that scan; two exports to one name kept the second)."""
    from pathlib import Path

    def key(p):
        return Path(p).resolve()

    read = set()
    for p in inputs:
        if p is None:
            continue
        p = Path(p)
        read.add(key(p))
        if p.is_dir():
            read.update(key(c) for c in p.iterdir())
    seen: dict = {}
    for flag, path, *suffixes in outputs:
        if not path:
            continue
        if suffixes and Path(path).suffix.lower() not in suffixes[0]:
            raise UserError(f"{flag} {path}: the file name must end in {' or '.join(suffixes[0])}")
        check_output_file(path, flag)
        k = key(path)
        if k in read:
            raise UserError(f"{flag} {path}: that is a file this command reads (or one in the folder it reads); "
                            "give another name")
        if k in seen:
            raise UserError(f"{flag} {path}: {seen[k]} writes the same file; give each output its own name")
        seen[k] = flag
        if not overwrite and Path(path).exists():
            raise UserError(f"{flag} {path}: the file exists; give another name, move it away, or add "
                            "--overwrite to replace it")


def output_dir(path, flag: str):
    """The output directory ``path`` (given with ``flag``), created if missing; a UserError naming the
    flag when it cannot be.  Returns it as a Path."""
    from pathlib import Path

    out = Path(path)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"{flag} {out}: cannot create the directory ({exc.strerror or exc})") from None
    return out


def as_table(value, key: str, where: str) -> Mapping:
    """``[key]`` of a TOML file, which must be a table (``tracker = 1`` gave "'int' object is not
    iterable" from deep inside the loader)."""
    if not isinstance(value, Mapping):
        raise UserError(f"{where}: [{key}] must be a table, got {value!r}")
    return value


def check_keys(data: Mapping, allowed: Sequence[str], where: str) -> None:
    if not isinstance(data, Mapping):
        raise UserError(f"{where}: expected a table/mapping, got {type(data).__name__}")
    unknown = sorted(set(data) - set(allowed))
    if unknown:
        raise UserError(f"{where}: unknown key(s) {', '.join(map(repr, unknown))}; "
                        f"allowed keys: {', '.join(sorted(allowed))}")


def as_float(value, key: str, where: str, *, lo: float | None = None, hi: float | None = None,
             lo_open: bool = False, allow_none: bool = False) -> float | None:
    if value is None and allow_none:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise UserError(f"{where}: {key} must be a finite number, got {value!r}")
    v = float(value)
    if lo is not None and (v < lo or (lo_open and v <= lo)):
        rel = ">" if lo_open else ">="
        raise UserError(f"{where}: {key} must be {rel} {lo}, got {v!r}")
    if hi is not None and v > hi:
        raise UserError(f"{where}: {key} must be <= {hi}, got {v!r}")
    return v


def as_choice(value, key: str, where: str, choices: Sequence[str]) -> str:
    if value not in choices:
        raise UserError(f"{where}: {key} must be one of {', '.join(map(repr, choices))}, got {value!r}")
    return value


def as_path_text(value, key: str, where: str, what: str) -> str:
    """A file name given in a config: a non-empty string without a NUL character (a NUL reached the OS
    as "ValueError: embedded null byte", a traceback); ``what`` says what the file is, for the error."""
    if not isinstance(value, str) or not value or "\x00" in value:
        nul = ", without a NUL character" if isinstance(value, str) and "\x00" in value else ""
        raise UserError(f"{where}: {key} must be {what}{nul}")
    return value


def as_bool(value, key: str, where: str) -> bool:
    if not isinstance(value, bool):
        raise UserError(f"{where}: {key} must be true or false, got {value!r}")
    return value


def as_vec(value, key: str, where: str, n: int) -> tuple[float, ...]:
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence) or len(value) != n:
        raise UserError(f"{where}: {key} must be a list of {n} numbers, got {value!r}")
    return tuple(as_float(v, f"{key}[{i}]", where) for i, v in enumerate(value))


def read_toml(path, what: str, hint: str = "") -> tuple[dict, str]:
    """Read a user's TOML file: ``(data, text)``, or a UserError naming the file and the problem.

    ``what`` names the kind of file in messages ("scene", "daemon config", ...); ``hint`` is added
    when the file does not exist (e.g. where examples are).
    """
    import tomllib
    from pathlib import Path

    path = Path(path)
    try:
        text = read_small_text(path, what)
    except FileNotFoundError:
        raise UserError(f"{path}: no such {what} file{f' ({hint})' if hint else ''}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise UserError(f"{path}: cannot read the {what} ({exc})") from None
    try:
        return tomllib.loads(text), text
    except tomllib.TOMLDecodeError as exc:
        raise UserError(f"{path}: not valid TOML ({exc})") from None
    except RecursionError:    # tomllib recurses per level: a file nested 1000 deep
        raise UserError(f"{path}: not a usable {what}: arrays or tables nested too deep") from None


#: the largest text file a user gives as configuration (a scene, a config, a speed table) [bytes]
MAX_CONFIG_BYTES = 16 << 20


def read_small_text(path, what: str) -> str:
    """The text of a regular file of at most :data:`MAX_CONFIG_BYTES`: a device or a FIFO
    (``/dev/zero``: 3.5 GB, then MemoryError) or a huge file is a UserError naming it."""
    from pathlib import Path

    if "\x00" in str(path):      # the OS refuses it with "ValueError: embedded null byte" (a traceback)
        raise UserError(f"{str(path)!r}: the {what}'s file name holds a NUL character")
    path = Path(path)
    if path.exists() and not path.is_file():
        raise UserError(f"{path}: the {what} is not a regular file (a device, a FIFO or a directory)")
    with open(path, "rb") as fh:
        data = fh.read(MAX_CONFIG_BYTES + 1)
    if len(data) > MAX_CONFIG_BYTES:
        raise UserError(f"{path}: the {what} is over {MAX_CONFIG_BYTES >> 20} MiB: not a configuration file")
    return data.decode()


def dataclass_from_mapping(cls, data: Mapping, where: str, parsers: Mapping | None = None,
                           none_ok: Sequence[str] = ()):
    """A frozen dataclass of settings from its TOML table: unknown keys refused; a field whose default
    is a bool must be true or false, one that is an int an integer; ``parsers[name](value, where.name)`` reads a field of its own kind
    (a sub-table); every other value is a float (None allowed for the fields in ``none_ok``).  The
    class's own checks (``__post_init__``) name ``where`` too."""
    from dataclasses import fields

    check_keys(data, [f.name for f in fields(cls)], where)
    kw = {}
    for f in fields(cls):
        if f.name not in data:
            continue
        v = data[f.name]
        if parsers and f.name in parsers:
            kw[f.name] = parsers[f.name](v, f"{where}.{f.name}")
        elif isinstance(f.default, bool):
            if not isinstance(v, bool):
                raise UserError(f"{where}: {f.name} must be true or false, got {v!r}")
            kw[f.name] = v
        elif isinstance(f.default, int):
            if isinstance(v, bool) or not isinstance(v, int):
                raise UserError(f"{where}: {f.name} must be an integer, got {v!r}")
            kw[f.name] = v
        else:
            kw[f.name] = as_float(v, f.name, where, allow_none=f.name in none_ok)
    try:
        return cls(**kw)
    except UserError as exc:
        raise UserError(f"{where}: {exc}") from None
