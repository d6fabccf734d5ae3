"""The operator's word to a running daemon: pin a track of the multi-object tracker (issue 28), or unpin
(one role of :class:`foveatrack.daemon.runtime.Daemon`).

A daemon whose config has ``[tracker.sky]`` listens on a Unix datagram socket
(:meth:`foveatrack.device_config.DaemonConfig.control_socket_path`; the file is the daemon user's
alone, mode 0600, and no network sees it).  ``foveatrack daemon pin ID`` / ``unpin`` send one
request, a JSON object ``{"command": "pin", "track_id": N}`` or ``{"command": "unpin"}``, from a
socket of their own and wait for the one JSON answer ``{"ok", "message", "pinned", "priority",
"next_target", "frames", "tracks"}`` (the attention's after the last frame); ``{"command":
"tracks"}`` (``foveatrack daemon tracks``) only asks for the live confirmed tracks.

The loop's thread reads the socket between frames (without waiting: a request that is not there is
not waited for) and applies a request before the next frame is processed, so the pin is the
priority from that frame on; the event ``{"event": "track_pinned", "track_id": N | null}`` goes to the
recording's daemon channel before that frame's records, where replay applies it again
(:class:`foveatrack.replay.recorded.TrackPinned`).  Only a live confirmed track can be pinned (the
attention drops a pin on any other at its next frame): another id is refused, naming the live ones.
A pinned track that is deleted unpins itself (the recording's ``/tracks`` say ``pinned: null`` from
then on), and so does a rebase (a new sensor clock, a homed head: every track starts afresh).
"""

from __future__ import annotations

import json
import math
import os
import socket
import stat
from pathlib import Path

from foveatrack.daemon.record_queue import _job_event
from foveatrack.errors import UserError
from foveatrack.recording.records import ns

MAX_DATAGRAM = 65536
#: requests read per pass of the loop (more wait for the next pass: the loop is not held up by a flood)
MAX_REQUESTS_PER_PASS = 8


class ControlSocket:
    """The daemon's end: a non-blocking Unix datagram socket bound at ``path``.  A socket file left
    by a daemon that was killed is replaced; one where a daemon still answers is an error."""

    def __init__(self, path: Path, where: str):
        self.path = Path(path)
        if self.path.exists() or self.path.is_symlink():
            if not stat.S_ISSOCK(os.lstat(self.path).st_mode):
                raise UserError(f"{where}: control socket {self.path} exists and is not a socket; remove it or "
                                "set [daemon] control_socket to another path")
            probe = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
            try:
                probe.connect(str(self.path))
            except (ConnectionRefusedError, FileNotFoundError):
                self.path.unlink(missing_ok=True)    # a killed daemon's: nobody reads it
            except OSError as exc:
                raise UserError(f"{where}: control socket {self.path}: {exc.strerror or exc}") from None
            else:
                raise UserError(f"{where}: another daemon listens on control socket {self.path}; stop it, or "
                                "set [daemon] control_socket to another path")
            finally:
                probe.close()
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        try:
            old = os.umask(0o177)          # the file is born 0600: no other user can pin
            try:
                sock.bind(str(self.path))
            finally:
                os.umask(old)
        except OSError as exc:
            sock.close()
            raise UserError(f"{where}: cannot create control socket {self.path} ([daemon] control_socket): "
                            f"{exc.strerror or exc}") from None
        sock.setblocking(False)
        self.sock = sock
        self._ino = os.stat(self.path).st_ino

    def requests(self) -> list[tuple[object, dict | None, str]]:
        """The requests waiting (at most :data:`MAX_REQUESTS_PER_PASS`): ``(sender, request, error)``,
        the request None when it was not a JSON object (``error`` says what it was)."""
        out = []
        for _ in range(MAX_REQUESTS_PER_PASS):
            try:
                data, addr = self.sock.recvfrom(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                break
            try:
                req = json.loads(data.decode("utf-8"))
            except (UnicodeDecodeError, ValueError):
                out.append((addr, None, f"not a JSON request ({len(data)} bytes)"))
                continue
            if not isinstance(req, dict):
                out.append((addr, None, f"the request is not a JSON object but {type(req).__name__}"))
                continue
            out.append((addr, req, ""))
        return out

    def answer(self, addr, reply: dict) -> None:
        """Send ``reply`` to ``addr`` (a client that has gone, or never bound a name, is not waited for)."""
        if not addr:
            return
        try:
            self.sock.sendto(json.dumps(reply).encode("utf-8"), addr)
        except OSError:
            pass

    def close(self) -> None:
        self.sock.close()
        try:
            if os.stat(self.path).st_ino == self._ino:      # ours, not a later daemon's
                self.path.unlink()
        except OSError:
            pass


def ask_daemon(path: Path, request: dict, timeout_s: float = 5.0) -> dict:
    """The client's end: send ``request`` to the daemon's control socket at ``path`` and return its
    answer; a UserError saying what was wrong when there is no daemon there or it does not answer."""
    path = Path(path)
    if not path.exists():
        raise UserError(f"no daemon is running there: no control socket at {path} (a daemon whose config has "
                        "[tracker.sky] creates it while it runs)")
    if not stat.S_ISSOCK(os.stat(path).st_mode):
        raise UserError(f"{path} is not a control socket (not a socket at all): check [daemon] control_socket; "
                        "a daemon will not start with that path either")
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    try:
        sock.bind("")              # an abstract name of our own (Linux autobind): the answer's address
        sock.settimeout(timeout_s)
        try:
            sock.connect(str(path))
            sock.send(json.dumps(request).encode("utf-8"))
        except ConnectionRefusedError:
            raise UserError(f"no daemon is running there: nothing listens on control socket {path} (left by a "
                            "daemon that was killed; the next start replaces it)") from None
        except PermissionError:
            raise UserError(f"control socket {path}: permission denied (the daemon runs as another user; "
                            "only its user may pin)") from None
        except OSError as exc:
            raise UserError(f"control socket {path}: {exc.strerror or exc}") from None
        try:
            data = sock.recv(MAX_DATAGRAM)
        except TimeoutError:
            raise UserError(f"the daemon at {path} did not answer within {timeout_s:g} s (its log says what it "
                            "is doing)") from None
        except OSError as exc:
            raise UserError(f"control socket {path}: {exc.strerror or exc}") from None
    finally:
        sock.close()
    try:
        reply = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, ValueError):
        raise UserError(f"the daemon at {path} answered something that is not JSON ({len(data)} bytes)") from None
    if not isinstance(reply, dict) or not isinstance(reply.get("message"), str):
        raise UserError(f"the daemon at {path} answered {reply!r}, not a reply")
    return reply


def describe_track(v) -> str:
    """``3 (drone, 25.1 m)``: a track's id, label and distance from the pivot."""
    x, y, z = (float(c) for c in v.xyz_m)
    return f"{v.track_id} ({v.label}, {math.sqrt(x * x + y * y + z * z):.1f} m)"


class Operator:
    """The daemon's side of the operator's requests (a mixin of ``Daemon``; ``control``: its
    :class:`ControlSocket`, None where the daemon runs the paper's tracker)."""

    def _open_control(self) -> None:
        """The control socket, where the multi-object tracker runs (after the links: a path that cannot
        be used closes them)."""
        if not hasattr(self.tracker, "pin"):
            return
        path = self.cfg.control_socket_path()
        try:
            self.cfg.check_control_socket()
            if not path.parent.is_dir():      # the recording's directory, which make_dirs lets us create
                try:
                    path.parent.mkdir(parents=True, exist_ok=True)
                except OSError as exc:
                    raise UserError(f"{self.cfg.path} [daemon] control_socket: cannot create {path.parent}: "
                                    f"{exc.strerror or exc}") from None
            self.control = ControlSocket(path, f"{self.cfg.path} [daemon]")
        except UserError:
            self.client.close()
            self.head.close()
            raise
        self.counters["operator_pins"] = 0     # before the threads that read the counters start
        self.counters["operator_unpins"] = 0
        self.log.event("control_socket", path=str(path))

    def _close_control(self) -> None:
        if self.control is not None:
            self.control.close()
            self.control = None

    def _serve_operator(self) -> None:
        """Between frames, on the loop's thread: answer every request waiting (none: nothing waits)."""
        if self.control is None:
            return
        for addr, req, error in self.control.requests():
            reply = self._operator_request(req) if req is not None else self._reply(False, error)
            self.control.answer(addr, reply)

    def _reply(self, ok: bool, message: str) -> dict:
        ctl = self.tracker
        live = ctl.confirmed_tracks()
        last = ctl.last_output
        return {"ok": ok, "message": message, "pinned": ctl.pinned, "priority": ctl.attention.priority,
                "next_target": None if last is None else last.next_target,
                "frames": self.counters["frames"],
                "tracks": [{"track_id": int(v.track_id), "label": str(v.label),
                            "xyz_m": [float(c) for c in v.xyz_m]} for v in live]}

    def _operator_request(self, req: dict) -> dict:
        cmd = req.get("command")
        if cmd not in ("pin", "unpin", "tracks"):
            return self._reply(False, f"unknown command {cmd!r} (the daemon takes 'pin', 'unpin' and 'tracks')")
        ctl = self.tracker
        live = ctl.confirmed_tracks()
        names = ", ".join(describe_track(v) for v in live) or "none"
        if cmd == "tracks":
            pinned = "" if ctl.pinned is None else f"; pinned: {ctl.pinned}"
            return self._reply(True, f"live confirmed tracks: {names}{pinned}")
        if cmd == "unpin":
            was = ctl.pinned
            if was is None:       # nothing to change: no event, nothing recorded
                return self._reply(True, "no track was pinned; none is")
            self._pin(None)
            return self._reply(True, f"unpinned track {was}: the fovea's priority is the highest threat again")
        tid = req.get("track_id")
        if isinstance(tid, bool) or not isinstance(tid, int) or tid < 0:
            return self._reply(False, f"track id must be a whole number >= 0, got {tid!r}")
        if self.pose_state is not None:
            return self._reply(False, f"the head's pose is unknown ({self.pose_state}): no track is followed "
                               "until it is known again, and then every track starts afresh")
        v = next((v for v in live if v.track_id == tid), None)
        if v is None:
            return self._reply(False, f"track {tid} is not a live confirmed track; nothing pinned "
                               f"(live confirmed tracks: {names})")
        self._pin(tid)
        held = self.tracker.attention.cfg.pin_holds_fovea
        return self._reply(True, f"pinned track {describe_track(v)}: "
                           + ("the fovea holds on it from the next frame while it lives (no revisits of the others)"
                              if held else "the fovea's priority from the next frame while it lives"))

    def _pin(self, track_id: int | None) -> None:
        """Apply the pin and record it before the next frame (replay applies it at the same place)."""
        self.tracker.pin(track_id)
        t_s = self.last_frame_end_s if self.last_frame_end_s is not None else 0.0
        self.counters["operator_pins" if track_id is not None else "operator_unpins"] += 1
        self.log.event("track_pinned", track_id=track_id, frames=self.counters["frames"])
        self._record(_job_event, ns(t_s), {"event": "track_pinned", "track_id": track_id})
