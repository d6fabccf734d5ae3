"""The live view: a recording's channels served over Foxglove's WebSocket protocol by the Foxglove
SDK's server, on loopback.

The server is a second sink of the writer's ``foxglove.Context`` (:class:`RecordingWriter`, with
``path=None`` when nothing is written to disk): a client (Foxglove's app: "Open connection" ->
``ws://127.0.0.1:PORT``) sees exactly the channels of a recording, as they are logged.  PORT is
served by :class:`foveatrack.recording.origin_gate.OriginGate`, which refuses a web page's connection
unless its ``Origin`` is allowed (``--live-origin``; Foxglove's web app is), in front of the SDK's
server on a free loopback port.
"""

from __future__ import annotations

import ipaddress
import time

from foveatrack.errors import UserError

DEFAULT_PORT = 8765


def check_port(port, what: str = "--live") -> int:
    """A TCP port 0..65535 (0: any free port), else a UserError naming ``what``."""
    try:
        p = int(port)
    except (TypeError, ValueError):
        raise UserError(f"{what} {port!r}: a port must be a whole number 0-65535") from None
    if not 0 <= p <= 65535:
        raise UserError(f"{what} {p}: a port must be 0-65535 (0: any free port)")
    return p


DEFAULT_LINGER_S = 30.0    # after a run, the server stays this long at most while a viewer is connected


class _Viewers:
    """The SDK's server listener: who is subscribed to what.  A viewer is a client with at least
    one subscription (the SDK tells subscriptions, not connections; a disconnect unsubscribes all)."""

    def __init__(self):
        import threading

        self._subs: set[tuple[int, int]] = set()
        self.cond = threading.Condition()
        self.changes = 0

    def on_subscribe(self, client, channel) -> None:
        with self.cond:
            self._subs.add((client.id, channel.id))
            self.changes += 1
            self.cond.notify_all()

    def on_unsubscribe(self, client, channel) -> None:
        with self.cond:
            self._subs.discard((client.id, channel.id))
            self.cond.notify_all()

    @property
    def count(self) -> int:
        with self.cond:
            return len({c for c, _ch in self._subs})


class LiveServer:
    """Serve ``context``'s channels on ``ws://host:port`` (host: loopback only; port 0: any free one).

    ``port`` is the bound port.  ``stop()`` closes it (also on exit as a context manager);
    :meth:`wait_for_viewer` and :meth:`linger` wait for a viewer to come and to go.
    """

    def __init__(self, context, port: int = DEFAULT_PORT, host: str = "127.0.0.1", name: str = "foveatrack",
                 allowed_origins=(), say=None):
        import sys

        import foxglove

        from foveatrack.recording.origin_gate import OriginGate

        try:
            loopback = ipaddress.ip_address(host).is_loopback
        except ValueError:
            loopback = False
        if not loopback:
            raise UserError(f"live view host {host!r}: only a loopback address (127.0.0.0/8, ::1) is served")
        port = check_port(port)
        for o in allowed_origins:
            if o != "*" and "://" not in o:
                raise UserError(f"--live-origin {o!r}: an origin is scheme://host[:port], e.g. http://localhost:3000 "
                                f"(or * for any web page)")
        if say is None:
            def say(text):
                print(text, file=sys.stderr, flush=True)

        def refused(origin):
            say(f"live view: refused a connection from the web page at origin {origin!r} (allow it with "
                f"--live-origin {origin})")

        self._server = self._gate = None
        try:
            self._viewers = _Viewers()
            # the SDK on a free port; the port asked for is the gate's, which checks each handshake's Origin
            self._server = foxglove.start_server(name=name, host=host, port=0, context=context,
                                                 server_listener=self._viewers)
            self._gate = OriginGate(host, port, int(self._server.port), allowed_origins, refused)
        except Exception as exc:  # noqa: BLE001 - the SDK's own error type, or OSError, for a port in use
            if self._server is not None:
                self._server.stop()
                self._server = None
            raise UserError(f"--live {port}: cannot serve on {host}:{port} ({exc}); choose another port "
                            f"or 0 for any free one") from None
        self.host = host
        self.port = int(self._gate.port)

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    @property
    def viewers(self) -> int:
        """Clients subscribed to at least one channel now."""
        return self._viewers.count

    def wait_for_viewer(self, timeout_s: float, settle_s: float = 0.25) -> bool:
        """Wait until a viewer subscribes (True) or ``timeout_s`` passes (False); then until its
        subscriptions stop coming for ``settle_s`` (the SDK reports them one channel at a time), so
        that it gets the first message of every channel it asked for."""
        v = self._viewers
        with v.cond:
            if not v.cond.wait_for(lambda: v.count > 0, timeout=max(0.0, timeout_s)):
                return False
            for _ in range(20):     # at most 20 settle periods
                seen = v.changes
                v.cond.wait_for(lambda: v.changes != seen, timeout=settle_s)
                if v.changes == seen:
                    break
            return True

    def linger(self, timeout_s: float = DEFAULT_LINGER_S, say=None) -> bool:
        """After a run: while a viewer is connected, keep serving until it leaves or ``timeout_s``
        passes (True: every viewer left; also when none was there)."""
        if self.viewers == 0 or timeout_s <= 0:
            return self.viewers == 0
        if say is not None:
            say(f"live view: the run has ended; serving until the viewer disconnects (at most "
                f"{timeout_s:g} s, --linger-s)")
        with self._viewers.cond:
            return self._viewers.cond.wait_for(lambda: self._viewers.count == 0, timeout=timeout_s)

    def stop(self) -> None:
        if self._gate is not None:
            self._gate.stop()
            self._gate = None
        if self._server is not None:
            self._server.stop()
            self._server = None

    def __enter__(self) -> "LiveServer":
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


MAX_WAIT_FOR_CLIENT_S = 3600.0     # --wait-s: an hour is plenty; inf made time.sleep overflow


class Pacer:
    """Holds a producer of timestamped messages to ``speed`` x real time: :meth:`wait` sleeps until
    the wall clock has caught up with a virtual time [s] (speed > 0; speed = inf: no waiting)."""

    #: the slowest pace taken: below it one recorded second would be hours of waiting
    MIN_SPEED = 1e-3
    #: a step of recorded time longer than this [s] (a sensor clock that jumped, e.g. power-on time to
    #: PTP time) or back in time is not waited for: the pace starts again at that message
    MAX_STEP_S = 10.0

    def __init__(self, speed: float = 1.0):
        if not (speed >= self.MIN_SPEED):       # also NaN
            raise UserError(f"--speed {speed}: must be at least {self.MIN_SPEED:g} (1 = real time, 2 = twice as "
                            f"fast, inf = no waiting)")
        self.speed = float(speed)
        self._t0_wall: float | None = None
        self._t0_virtual = 0.0
        self._last_virtual = 0.0
        self.jumps = 0          # recorded-time steps not waited for (see MAX_STEP_S)

    def wait(self, t_virtual_s: float) -> None:
        now = time.monotonic()
        t = float(t_virtual_s)
        if self._t0_wall is None or not (0.0 <= t - self._last_virtual <= self.MAX_STEP_S):
            if self._t0_wall is not None:
                self.jumps += 1
            self._t0_wall, self._t0_virtual, self._last_virtual = now, t, t
            return
        self._last_virtual = t
        due = self._t0_wall + (t - self._t0_virtual) / self.speed
        if due > now:
            time.sleep(due - now)


def _log_time_of(info: dict) -> int | str:
    """The log clock a recording was written with (its metadata's ``log_time``): the offset [ns], or
    "host" (a daemon's recording is served in the host's time now); 0 for one made before UTC log times."""
    text = str(info.get("log_time", "t_ns+0"))
    if text == "host_utc":
        return "host"
    try:
        return max(0, int(text.removeprefix("t_ns+")))
    except ValueError:
        return 0


def stream_recording(path, port: int = DEFAULT_PORT, speed: float = 1.0, wait_for_client_s: float = 0.0,
                     say=None, linger_s: float = 0.0, allowed_origins=()) -> int:
    """Serve a recording on the live view, paced at ``speed`` x its recorded time: its records as
    recorded, with the transforms and scene entities drawn from them (a format-1 recording too).
    ``wait_for_client_s``: wait until a viewer subscribes, at most that long, before the first message;
    ``linger_s``: after the last, keep serving a connected viewer until it leaves, at most that long.
    Returns the number of messages served."""
    from foveatrack.recording.format import IMU, POINTS
    from foveatrack.recording.reader import RecordingReader
    from foveatrack.recording.writer import RecordingWriter

    if not 0.0 <= wait_for_client_s <= MAX_WAIT_FOR_CLIENT_S:
        raise UserError(f"--wait-s {wait_for_client_s}: must be 0..{MAX_WAIT_FOR_CLIENT_S:g} s")
    pacer = Pacer(speed)
    reader = RecordingReader(path)
    w = RecordingWriter(None, reader.meta, log_time=_log_time_of(reader.info))
    n = 0
    with LiveServer(w.context, port, allowed_origins=allowed_origins, say=say) as live:
        if say is not None:
            say(f"live view on {live.url} (Foxglove: Open connection -> Foxglove WebSocket), "
                f"{speed:g}x recorded time")
        if wait_for_client_s > 0:
            if say is not None:
                say(f"live view: waiting up to {wait_for_client_s:g} s for a viewer to connect (--wait-s)")
            seen = live.wait_for_viewer(wait_for_client_s)
            if say is not None:
                say("live view: a viewer connected; streaming" if seen else
                    f"live view: no viewer within {wait_for_client_s:g} s; streaming anyway")
        for m in reader.messages():
            pacer.wait(m.t_ns * 1e-9)
            if m.channel == POINTS:
                f = m.record
                w.write_points(f.t_ns, f.frame_index, f.xyz, f.t_ns_points, f.reflectivity)
            elif m.channel == IMU:
                b = m.record
                w.write_imu(b.t_ns, b.frame_id, b.t_s, b.gyro_rad_s, b.accel_g)
            else:
                rec = {k: v for k, v in m.record.items() if k != "t_ns"}
                w.write(m.channel, m.t_ns, rec)
            n += 1
        w.close()
        live.linger(linger_s, say)
    return n
