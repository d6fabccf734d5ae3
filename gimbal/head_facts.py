"""What a driver knows of its head and link, in one place: stops, start pose, protocol, baud.

The head reports nothing, so these facts are configured, once: ``[gimbal]`` in a scene (the simulated
unit's own stops), ``[head]`` in a daemon config.  The tracker's dead reckoning and its tilt-stop logic,
and the command gate, all read them from here (:meth:`foveatrack.tracker.TrackerConfig.with_head`
applies them; a ``[tracker]`` table may not contradict them).

Every default of these facts is declared here once and the other places read it: the simulated
PTS-303 family's stops (:mod:`gimbal.pts303h.params`), the tracker's configuration
(:class:`foveatrack.tracker.TrackerConfig`: stops, link latency), the command gate's limits
(:class:`foveatrack.gate.Limits`), a daemon's ``[head]`` and a scene's ``[gate]``.

tilt_limits_deg : (lo, hi) [deg]   the tilt stops (tilt + = up); pan is continuous (PTS-303: -30, 60)
pan0_deg, tilt0_deg : [deg]        where the head points at start (after homing)
protocol : "D" | "P"               Pelco-D or Pelco-P frames
baud : int [bit/s]                 the serial line (8N1)
send_delay_s : >= 0 [s] or None    frame end -> command written, where the driver fixes it (the
                                   simulator); None where the driver measures each send (the daemon)

The limits every command passes on its way to this head (the command gate; the operator's choice):
max_pan_byte, max_tilt_byte : 0..63   highest speed byte allowed per axis
allow_turbo : bool                    may pan use the turbo byte (default not: the fastest speed is
                                      the least known, and an unknown head is not driven at it)
tilt_margin_deg : >= 0 [deg]          no tilt toward a stop within this of it (the gate's 2 deg, inside
                                      the tracker's own 3 deg: it acts only when the tracker did not)
"""

from __future__ import annotations

from dataclasses import dataclass

from gimbal.pelco import MAX_SPEED_BYTE, PAN_TURBO, frame_time_s

#: The PTS-303 family's tilt stops [deg] (the simulated family's, gimbal.pts303h.params, and the
#: default of every driver's configuration).
PTS303_TILT_STOPS_DEG = (-30.0, 60.0)
#: The turbo pan byte (Pelco-D's 0xFF; Pelco-P's 0x40 is decoded to it): the one declaration.
TURBO = PAN_TURBO

# The keys of a tracker configuration that are facts of the head and its link, not tracker settings.
HEAD_KEYS = ("pan0_deg", "tilt0_deg", "tilt_limits_deg", "latency_s", "send_delay_s")


@dataclass(frozen=True)
class HeadFacts:
    tilt_limits_deg: tuple[float, float] = PTS303_TILT_STOPS_DEG
    pan0_deg: float = 0.0
    tilt0_deg: float = 0.0
    protocol: str = "D"
    baud: int = 9600
    send_delay_s: float | None = None
    max_pan_byte: int = MAX_SPEED_BYTE
    max_tilt_byte: int = MAX_SPEED_BYTE
    allow_turbo: bool = False
    tilt_margin_deg: float = 2.0

    @property
    def frame_time_s(self) -> float:
        """One command frame on the wire [s]: the link latency the dead reckoning adds to a send."""
        return frame_time_s(self.protocol, self.baud)

    def tracker_values(self) -> dict:
        """The tracker configuration's head keys, as these facts give them."""
        out = {"pan0_deg": float(self.pan0_deg), "tilt0_deg": float(self.tilt0_deg),
               "tilt_limits_deg": (float(self.tilt_limits_deg[0]), float(self.tilt_limits_deg[1])),
               "latency_s": self.frame_time_s}
        if self.send_delay_s is not None:
            out["send_delay_s"] = float(self.send_delay_s)
        return out


#: The facts of a PTS-303 on Pelco-D at 9600 baud with the default limits: every default in one object.
DEFAULT_HEAD = HeadFacts()
