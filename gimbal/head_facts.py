"""What a driver knows of its head and link, in one place: stops, start pose, protocol, baud.

The head reports nothing, so these facts are configured, once: ``[gimbal]`` in a scene (the simulated
unit's own stops), ``[head]`` in a daemon config.  The tracker's dead reckoning and its tilt-stop logic,
and the command gate, all read them from here (:meth:`foveatrack.tracker.TrackerConfig.with_head`
applies them; a ``[tracker]`` table may not contradict them).

tilt_limits_deg : (lo, hi) [deg]   the tilt stops (tilt + = up); pan is continuous
pan0_deg, tilt0_deg : [deg]        where the head points at start (after homing)
protocol : "D" | "P"               Pelco-D or Pelco-P frames
baud : int [bit/s]                 the serial line (8N1)
send_delay_s : >= 0 [s] or None    frame end -> command written, where the driver fixes it (the
                                   simulator); None where the driver measures each send (the daemon)
"""

from __future__ import annotations

from dataclasses import dataclass

from gimbal.pelco import frame_time_s

# The keys of a tracker configuration that are facts of the head and its link, not tracker settings.
HEAD_KEYS = ("pan0_deg", "tilt0_deg", "tilt_limits_deg", "latency_s", "send_delay_s")


@dataclass(frozen=True)
class HeadFacts:
    tilt_limits_deg: tuple[float, float]
    pan0_deg: float = 0.0
    tilt0_deg: float = 0.0
    protocol: str = "D"
    baud: int = 9600
    send_delay_s: float | None = None

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
