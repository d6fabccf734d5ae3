"""``foveatrack gimbal ...``: the virtual PTS-303H head and its speed curves.

* ``foveatrack gimbal serve``: serve a virtual head on a pseudo-terminal.  The first line on stdout
  is the device path; open it with any Pelco-D/P controller (pyserial:
  ``serial.serial_for_url(path, 9600)``).  ``--truth FILE`` receives the true state as JSON lines.
  Stops cleanly on SIGINT / SIGTERM (exit status 0).  ``--link PATH`` is held by ``PATH.lock``
  while served: a second server on PATH is refused, a link left by a killed one is replaced.
* ``foveatrack gimbal curves --plot F.png``: speed vs speed byte for two (or more) unit seeds, the
  reason the tracker must calibrate (paper, Appendix D, "Gimbal angle calibration").
"""

from __future__ import annotations

import argparse
import signal
import sys

from foveatrack.config_util import seed_arg
from foveatrack.errors import UserError


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "gimbal", help="the virtual PTS-303H pan/tilt head (serve on a pty, plot speed curves)"
    )
    sub = p.add_subparsers(dest="gimbal_command", metavar="GIMBAL_COMMAND", required=True)

    s = sub.add_parser("serve", help="serve a virtual head on a pseudo-terminal")
    s.add_argument("--baud", type=int, default=9600, help="line speed for byte pacing [bit/s]")
    s.add_argument("--address", type=int, default=1, help="Pelco address (DIP switch), 1-255")
    s.add_argument("--unit-seed", type=seed_arg, default=0, help="which unit (speed curve, ripple)")
    s.add_argument("--feedback", choices=("none", "at-rest", "always"), default="none",
                   help="position-query answers: none (the paper's head), at-rest, always")
    s.add_argument("--family", default="pts-303", help="head family: pts-303 or heavy-worm")
    s.add_argument("--truth", metavar="FILE", help="write the true state as JSON lines here")
    s.add_argument("--truth-period-s", type=float, default=0.02, help="truth line period [s]")
    s.add_argument("--link", metavar="PATH", help="also make a symlink PATH to the pty (PATH.lock marks it "
                   "while served: a second server on PATH is refused)")
    s.add_argument("--pan0-deg", type=float, default=0.0, help="the head's pan at power-on [deg] (default 0)")
    s.add_argument("--tilt0-deg", type=float, default=0.0, help="the head's tilt at power-on [deg] (default 0)")
    s.set_defaults(func=cmd_serve)

    c = sub.add_parser("curves", help="plot true speed vs speed byte for unit seeds")
    c.add_argument("--plot", metavar="F.png", required=True, help="output PNG")
    c.add_argument("--unit-seeds", type=seed_arg, nargs="+", default=[0, 1], help="simulated units to plot (default 0 1)")
    c.add_argument("--family", default="pts-303", help="head family: pts-303 or heavy-worm")
    c.set_defaults(func=cmd_curves)


def _head(args, unit_seed: int, feedback: str = "none", address: int = 1, **kw):
    from gimbal.errors import GimbalError
    from gimbal.pts303h import PTS303H, HeadParams

    try:
        params = HeadParams.for_family(args.family)
        return PTS303H(params, unit_seed=unit_seed, feedback=feedback, address=address, **kw)
    except GimbalError as exc:
        raise UserError(str(exc)) from exc


def cmd_serve(args: argparse.Namespace) -> int:
    import time

    from sim.virtual_head import VirtualHeadServer

    if not 1 <= args.address <= 255:
        raise UserError(f"--address {args.address} is not allowed; use 1-255")
    if args.baud <= 0:
        raise UserError(f"--baud {args.baud} is not allowed; use a positive rate such as 9600")
    if args.truth_period_s <= 0:
        raise UserError("--truth-period-s must be > 0")
    head = _head(args, args.unit_seed, args.feedback, args.address,
                 pan0_deg=args.pan0_deg, tilt0_deg=args.tilt0_deg)
    stop = {"flag": False}

    def _on_signal(signum, frame):  # noqa: ARG001
        stop["flag"] = True

    old = {sig: signal.signal(sig, _on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    power_cuts = {"n": 0}

    def _on_power_cut(signum, frame):  # noqa: ARG001
        power_cuts["n"] += 1

    old[signal.SIGUSR1] = signal.signal(signal.SIGUSR1, _on_power_cut)
    truth = claim = None
    try:
        if args.truth:
            try:
                truth = open(args.truth, "w", buffering=1)
            except OSError as exc:
                raise UserError(f"--truth {args.truth}: cannot write ({exc.strerror})") from exc
        if args.link:
            _check_link_path(args.link)
            claim = _claim_link(args.link)
        server = VirtualHeadServer(head, time.monotonic, baud=args.baud, truth=truth,
                                   truth_period_s=args.truth_period_s, link_path=args.link)
        try:
            path = server.open()
        except OSError as exc:
            raise UserError(f"cannot create the pty or --link {args.link}: {exc}") from exc
        print(path, flush=True)
        print(f"virtual PTS-303H ({args.family}, unit {args.unit_seed}, address {args.address}, "
              f"{args.baud} baud, feedback {args.feedback}) on {server.path}; truth t_s = 0 at "
              f"time.monotonic() = {server.clock_zero:.6f}; Ctrl-C stops, SIGUSR1 cuts its power (the pty stays)",
              file=sys.stderr, flush=True)
        try:
            done = 0
            while not stop["flag"]:
                if power_cuts["n"] != done:     # SIGUSR1: a power cut behind the live link
                    done = power_cuts["n"]
                    server.power_cycle()
                    print(f"power cycled at head time {server.now():.6f} s", file=sys.stderr, flush=True)
                server.step()
        finally:
            server.close()
    finally:
        if claim is not None:
            _release_link(args.link, claim)
        if truth is not None:
            truth.close()
        for sig, handler in old.items():
            signal.signal(sig, handler)
    return 0


def cmd_curves(args: argparse.Namespace) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    b = np.arange(0x40)
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    for seed in args.unit_seeds:
        head = _head(args, seed)
        for ax, axis in zip(axes, ("pan", "tilt")):
            table = head.speed_table(axis)
            (line,) = ax.plot(b, table[b], marker=".", ms=3, label=f"unit seed {seed}")
            if axis == "pan":
                ax.axhline(table[0xFF], color=line.get_color(), ls=":", lw=1)
    for ax, axis in zip(axes, ("pan", "tilt")):
        ax.set_xlabel(f"{axis} speed byte (Pelco d{1 if axis == 'pan' else 2})")
        ax.set_ylabel("true speed [deg/s]")
        ax.set_title(f"{axis}" + (" (dotted: turbo 0xFF)" if axis == "pan" else ""))
        ax.grid(alpha=0.3)
        ax.legend()
    fig.suptitle(f"PTS-303H model ({args.family}): speed vs speed byte")
    try:
        fig.savefig(args.plot, dpi=120)
    except OSError as exc:
        raise UserError(f"--plot {args.plot}: cannot write ({exc.strerror})") from exc
    finally:
        plt.close(fig)
    print(args.plot)
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run just the ``gimbal`` group (``python -m foveatrack.cli.gimbal_cmd serve ...``),
    with the same error handling as ``foveatrack``; useful where other groups are absent."""
    parser = argparse.ArgumentParser(prog="foveatrack gimbal")
    register(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["gimbal", *(sys.argv[1:] if argv is None else argv)])
    try:
        return int(args.func(args) or 0)
    except UserError as exc:
        print(f"foveatrack: error: {exc}", file=sys.stderr)
        return 2



def _check_link_path(link: str) -> None:
    """--link names a symlink we create (or replace, if it is one): say plainly what is wrong with it.

    Without this a missing directory came out as an errno with our temporary name in it, and a regular
    file at the path would have been replaced by the link.
    """
    import os

    parent = os.path.dirname(os.path.abspath(link))
    if not os.path.isdir(parent):
        raise UserError(f"--link {link}: the directory {parent} does not exist")
    if os.path.lexists(link) and not os.path.islink(link):
        raise UserError(f"--link {link}: a file that is not a symlink is there already; "
                        "name another path (the link is replaced only if it is one)")


def _claim_link(link: str) -> int:
    """Hold ``LINK.lock`` (an exclusive flock) while this server serves --link LINK; return its fd.

    A second server on the same path took over the live head's link and, on exit, removed it.  The
    kernel drops the lock when its holder dies however it dies, so a link left by a killed server (its
    pty gone, or its number since reused) is replaced as before; only a live server's is refused.
    """
    import fcntl
    import os

    lock = f"{link}.lock"
    while True:
        try:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        except OSError as exc:
            raise UserError(f"--link {link}: cannot open its lock file {lock} ({exc.strerror})") from exc
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            pid = os.read(fd, 32).decode("ascii", "replace").strip()
            os.close(fd)
            who = f"process {pid}" if pid.isdigit() else "another process"
            target = f" (-> {os.readlink(link)})" if os.path.islink(link) else ""
            raise UserError(f"--link {link}{target} belongs to a virtual head that {who} still serves; stop "
                            f"that server first ({'kill ' + pid if pid.isdigit() else 'Ctrl-C'}), or name "
                            "another path") from None
        try:
            ours = os.path.samestat(os.fstat(fd), os.stat(lock))
        except FileNotFoundError:
            ours = False
        if ours:             # not a file its last holder removed as we opened it
            os.ftruncate(fd, 0)
            os.write(fd, f"{os.getpid()}\n".encode())
            return fd
        os.close(fd)


def _release_link(link: str, fd: int) -> None:
    """Remove ``LINK.lock`` while still holding it (the file is ours), then let it go."""
    import os

    try:
        os.unlink(f"{link}.lock")
    except OSError:
        pass
    os.close(fd)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
