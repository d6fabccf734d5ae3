"""``foveatrack lidar serve SCENE.toml``: the scene's lidar in real time as a Livox on UDP.

Registered by :func:`foveatrack.cli.lidar_cmd.register` through :func:`add_serve_parser`; the
simulator (:mod:`sim.lidar_server`) is imported only when the command runs.  The first stdout line is
``READY <ip> <cmd_port>``; on SIGINT/SIGTERM it prints its counters as one JSON line and exits 0.
Status lines go to stderr: the unit, then the scene time at every sampling start (scene time 0 is the
first one's, unless ``--clock start``), and once the stream passes the scene's ``duration_s``.
"""

from __future__ import annotations

import json
import os
import sys

from foveatrack.config_util import seed_arg
from foveatrack.errors import UserError, access_text


def add_serve_parser(lsub) -> None:
    """Add ``serve`` to the ``foveatrack lidar`` sub-commands."""
    p = lsub.add_parser("serve", help="run a scene's lidar in real time as a Livox (SDK v1 over UDP)")
    p.add_argument("scene", metavar="SCENE.toml", help="the scene whose lidar, targets and background to serve")
    p.add_argument("--bind-ip", "--host-ip", dest="bind_ip", default="127.0.0.1",
                   help="the virtual lidar's own address (default 127.0.0.1)")
    p.add_argument("--cmd-port", type=int, default=65000, help="its command port (65000 as a real Livox; 0 = any)")
    p.add_argument("--broadcast-ip", default="127.0.0.1", help="where discovery broadcasts go")
    p.add_argument("--broadcast-port", type=int, default=55000, help="host port of the broadcasts (55000)")
    p.add_argument("--packet-type", type=int, default=None, metavar="TYPE",
                   help="data type, one the preset's unit sends (default: its Cartesian single-return type: "
                        "0 for mid40/mid100/prototype, 2 for the others); a host can change it with the "
                        "coordinate-system and return-mode commands")
    p.add_argument("--time-scale", type=float, default=1.0, help="stream seconds per wall second")
    p.add_argument("--loss-rate", type=float, default=0.0, help="fraction of data packets dropped")
    p.add_argument("--seed", type=seed_arg, default=0, help="seed of the packet loss")
    p.add_argument("--head-truth", metavar="FILE",
                   help="follow the head served by 'foveatrack gimbal serve --truth FILE'")
    p.add_argument("--head-clock-zero", type=float, default=None, metavar="MONO",
                   help="that head's time.monotonic() at t_s = 0 (printed by gimbal serve; default: estimated)")
    p.add_argument("--log-control", metavar="FILE",
                   help="write every control datagram received and sent as JSON lines {dir, t_s, hex}")
    p.add_argument("--clock", choices=("sampling", "start"), default="sampling",
                   help="when scene time 0 is: when a host first starts sampling (default), or when the serve "
                        "starts (a host that connects late then meets the scene that far in)")
    p.add_argument("--duration-s", type=float, default=None,
                   help="stop after this many wall seconds from the start (past the scene's own duration_s "
                        "the serve goes on, and says so once)")
    p.set_defaults(func=cmd_serve)


def cmd_serve(args) -> int:
    from sim.lidar_server import serve_scene
    from sim.scene import load_scene

    scene = load_scene(args.scene)
    for w in scene.warnings():      # a drone under the ground or at the head is served, and never seen
        print(f"lidar serve: WARNING: {w}", file=sys.stderr, flush=True)
    if not args.time_scale > 0:
        raise UserError(f"--time-scale must be > 0, got {args.time_scale}")
    if args.duration_s is not None and not args.duration_s > 0:
        raise UserError(f"--duration-s must be > 0 (or absent: serve until Ctrl-C), got {args.duration_s}")
    if not 0 <= args.loss_rate < 1:
        raise UserError(f"--loss-rate must be in [0, 1), got {args.loss_rate}")
    if not 0 <= args.cmd_port <= 65535 or not 0 < args.broadcast_port <= 65535:
        raise UserError("--cmd-port must be in 0..65535 and --broadcast-port in 1..65535")
    if args.head_truth:
        _check_head_truth(args.head_truth)

    def ready(lidar):
        print(f"READY {lidar.address[0]} {lidar.cmd_port}", flush=True)
        u = lidar.unit
        if u.fallback:
            print(f"lidar serve: no Livox unit is known for scanner preset {scene.optics.name!r}; serving it as "
                  f"a generic {u.model}", file=sys.stderr, flush=True)
        print(f"Livox {u.model} (device type {lidar.dev_type}, broadcast code {lidar.broadcast_code}, firmware "
              f"{'.'.join(str(v) for v in u.firmware)}, data type {lidar.packet_type}"
              f"{', IMU 200 Hz' if u.has_imu else ''})", file=sys.stderr, flush=True)
        print(f"virtual {scene.optics.name} lidar for scene {scene.name!r} ({scene.optics.point_rate_hz:g} pts/s) "
              f"on {lidar.address[0]}:{lidar.cmd_port}, broadcasting to {args.broadcast_ip}:{args.broadcast_port}"
              f"{'; following head truth ' + args.head_truth if args.head_truth else ''}; Ctrl-C stops",
              file=sys.stderr, flush=True)
        when = "when a host first starts sampling" if args.clock == "sampling" else "now (--clock start)"
        print(f"lidar serve: the scene's clock starts {when}; the scene lasts {scene.duration_s:g} s",
              file=sys.stderr, flush=True)

    def status(line: str) -> None:
        print(f"lidar serve: {line}", file=sys.stderr, flush=True)

    log = _ControlLog(args.log_control) if args.log_control else None
    counters = serve_scene(
        scene, bind_ip=args.bind_ip, cmd_port=args.cmd_port, broadcast_addr=(args.broadcast_ip, args.broadcast_port),
        time_scale=args.time_scale, loss_rate=args.loss_rate, seed=args.seed, packet_type=args.packet_type,
        head_truth=args.head_truth, head_clock_zero=args.head_clock_zero, duration_s=args.duration_s, ready=ready,
        control_log=log, clock=args.clock, status=status)
    if log is not None:
        log.close()
    print(json.dumps({k: int(v) for k, v in sorted(counters.items())}), flush=True)
    return 0


class _ControlLog:
    """``--log-control FILE``: the virtual lidar appends (direction, bytes); one JSON line each."""

    def __init__(self, path: str):
        import time

        try:
            self._fh = open(path, "w")
        except OSError as exc:
            raise UserError(f"--log-control {path}: {exc.strerror}") from None
        self._t0 = time.monotonic()
        self._clock = time.monotonic

    def append(self, item) -> None:
        direction, buf = item
        self._fh.write(json.dumps({"dir": direction, "t_s": round(self._clock() - self._t0, 4), "hex": buf.hex()}) + "\n")
        self._fh.flush()

    def close(self) -> None:
        self._fh.close()


def _check_head_truth(path: str) -> None:
    """``--head-truth FILE`` in a directory that does not exist can never appear: an error (before, the
    lidar served with the head frozen at the scene's start pose and said nothing).  A file that does not
    exist yet is normal (the head serve may start later): one stderr line says it is awaited."""
    from pathlib import Path

    p = Path(path)
    parent = p.parent if str(p.parent) else Path(".")
    if p.is_dir():
        raise UserError(f"--head-truth {path}: is a directory; give the file 'foveatrack gimbal serve --truth' writes")
    if not parent.is_dir():
        raise UserError(f"--head-truth {path}: the directory {parent} does not exist, so the head's truth "
                        "can never appear there; give the file 'foveatrack gimbal serve --truth FILE' writes")
    if not p.exists():
        print(f"lidar serve: --head-truth {path} does not exist yet; waiting for it (the head stays at the "
              "scene's pan0/tilt0 until 'foveatrack gimbal serve --truth' writes it)", file=sys.stderr, flush=True)
    elif not os.access(p, os.R_OK):
        # served on with the head frozen at its start pose, saying it followed the file (head_truth_lines 0)
        raise UserError(f"--head-truth {path}: this user may not read it (Permission denied; "
                        f"{access_text(p)}), so the head could never be followed; run 'foveatrack gimbal "
                        "serve --truth' as this user, or let this user read the file")
