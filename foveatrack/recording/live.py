"""The live view: a recording's channels served over Foxglove's WebSocket protocol by the Foxglove
SDK's server, on loopback.

The server is a second sink of the writer's ``foxglove.Context`` (:class:`RecordingWriter`, with
``path=None`` when nothing is written to disk): a client (Foxglove's app: "Open connection" ->
``ws://127.0.0.1:PORT``) sees exactly the channels of a recording, as they are logged.
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


class LiveServer:
    """Serve ``context``'s channels on ``ws://host:port`` (host: loopback only; port 0: any free one).

    ``port`` is the bound port.  ``stop()`` closes it (also on exit as a context manager).
    """

    def __init__(self, context, port: int = DEFAULT_PORT, host: str = "127.0.0.1", name: str = "foveatrack"):
        import foxglove

        try:
            loopback = ipaddress.ip_address(host).is_loopback
        except ValueError:
            loopback = False
        if not loopback:
            raise UserError(f"live view host {host!r}: only a loopback address (127.0.0.0/8, ::1) is served")
        port = check_port(port)
        try:
            self._server = foxglove.start_server(name=name, host=host, port=port, context=context)
        except Exception as exc:  # noqa: BLE001 - the SDK's own error type for a port in use
            raise UserError(f"--live {port}: cannot serve on {host}:{port} ({exc}); choose another port "
                            f"or 0 for any free one") from None
        self.host = host
        self.port = int(self._server.port)

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"


    def stop(self) -> None:
        if self._server is not None:
            self._server.stop()
            self._server = None

    def __enter__(self) -> "LiveServer":
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


class Pacer:
    """Holds a producer of timestamped messages to ``speed`` x real time: :meth:`wait` sleeps until
    the wall clock has caught up with a virtual time [s] (speed > 0; speed = inf: no waiting)."""

    def __init__(self, speed: float = 1.0):
        if not speed > 0:
            raise UserError(f"--speed {speed}: must be > 0 (1 = real time, 2 = twice as fast)")
        self.speed = float(speed)
        self._t0_wall: float | None = None
        self._t0_virtual = 0.0

    def wait(self, t_virtual_s: float) -> None:
        now = time.monotonic()
        if self._t0_wall is None:
            self._t0_wall, self._t0_virtual = now, float(t_virtual_s)
            return
        due = self._t0_wall + (float(t_virtual_s) - self._t0_virtual) / self.speed
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
                     say=None) -> int:
    """Serve a recording on the live view, paced at ``speed`` x its recorded time: its records as
    recorded, with the transforms and scene entities drawn from them (a format-1 recording too).
    ``wait_for_client_s``: give a client that long to connect before the first message.  Returns the
    number of messages served."""
    from foveatrack.recording.format import IMU, POINTS
    from foveatrack.recording.reader import RecordingReader
    from foveatrack.recording.writer import RecordingWriter

    reader = RecordingReader(path)
    pacer = Pacer(speed)
    w = RecordingWriter(None, reader.meta, log_time=_log_time_of(reader.info))
    n = 0
    with LiveServer(w.context, port) as live:
        if say is not None:
            say(f"live view on {live.url} (Foxglove: Open connection -> Foxglove WebSocket), "
                f"{speed:g}x recorded time")
        if wait_for_client_s > 0:
            time.sleep(wait_for_client_s)
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
    return n
