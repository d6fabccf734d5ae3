"""The ``foveatrack`` command: one entry point for everything users run.

Each command group lives in its own module with a ``register(subparsers)`` function; this module only
assembles them.  Errors a user can cause are raised as :class:`UserError` and printed as one clear
line (exit status 2), never as a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from foveatrack.cli.stop_signals import interrupts_remembered
from foveatrack.errors import UserError

# Command-group modules, in the order `foveatrack --help` lists them.
COMMAND_MODULES = (
    "foveatrack.cli.demo_cmd",
    "foveatrack.cli.warmup_cmd",
    "foveatrack.cli.simulate_cmd",
    "foveatrack.cli.lidar_cmd",
    "foveatrack.cli.gimbal_cmd",
    "foveatrack.cli.calibrate_cmd",
    "foveatrack.cli.calibrate_imu_cmd",
    "foveatrack.cli.daemon_cmd",
    "foveatrack.cli.replay_cmd",
    "foveatrack.cli.track_cmd",
    "foveatrack.cli.export_cmd",
    "foveatrack.cli.recover_cmd",
    "foveatrack.cli.study_cmd",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="foveatrack",
        description="Foveal UAV-intruder tracking with a retina-like lidar on a pan/tilt head.",
        formatter_class=argparse.RawDescriptionHelpFormatter,   # keeps --version's two lines as written
    )
    from foveatrack.environment import describe

    # what a bug report needs: versions, CPU, numba target (benchmark headers print the same)
    parser.add_argument("--version", action="version", version=describe())
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    with interrupts_remembered():     # a Ctrl-C lost in a __del__ or weakref callback is raised again
        return _main(argv)


def _main(argv: list[str] | None) -> int:
    try:
        # inside the try: a Ctrl-C while the command modules import (a second or so) is an interruption too
        args = build_parser().parse_args(argv)
        from foveatrack.cli.kernel_cache import choose

        # before any command defines a kernel: a read-only install with no writable home crashed here
        note = choose()
        if note:
            print(note, file=sys.stderr, flush=True)
        return int(args.func(args) or 0)
    except UserError as exc:
        print(f"foveatrack: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # output piped into `head` and closed: not an error of ours
        sys.stderr.close()
        return 0
    except OSError as exc:
        # a file, directory or port the user named cannot be used (an --out, --plot or --export path
        # on a missing directory or a full disk): say which and why, without a traceback
        name = exc.filename if exc.filename is not None else ""
        print(f"foveatrack: error: {name}{': ' if name else ''}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("foveatrack: interrupted", file=sys.stderr)
        return 130
    except ImportError as exc:
        # a Ctrl-C inside a compiled module's initialisation (scipy's pybind11 ones) comes out as
        # "ImportError: initialization failed" caused by the KeyboardInterrupt
        if isinstance(exc.__cause__, KeyboardInterrupt):
            print("foveatrack: interrupted", file=sys.stderr)
            return 130
        raise


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
