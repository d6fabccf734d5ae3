"""A virtual lidar behind a faulty network (issue 26): ``python faulty_lidar.py SCENE BROADCAST_PORT
HEAD_TRUTH FAULT STATE_JSON`` serves ``SCENE`` as ``foveatrack lidar serve`` does, but its data packets
go through :class:`FaultyNetwork`, which from real packet ``START`` on duplicates, replays, swaps or
time-shifts them.  STATE_JSON gets ``{"fault_done": true}`` once the fault is over, and at exit the
lidar's counters with the network's (``real_sent``, ``injected``, ``swapped``)."""

from __future__ import annotations

import json
import sys
from collections import deque
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from foveatrack.livox.protocol import HEADER_DTYPE, IMU_DATA_TYPE   # noqa: E402

_TS = HEADER_DTYPE.fields["timestamp"][1]            # byte offset of the packet's first-point time
_DT = HEADER_DTYPE.fields["data_type"][1]

#: fault -> (first real packet it touches, packets it spans); a Mid-40 sends 1000 packets/s
FAULTS = {
    "ahead": (3000, 2001),       # one packet 50, 100, 150 ms ahead, 1 s apart
    "old5s": (6000, 1),          # 100 packets 5 s old, in a burst
    "resend50": (3000, 4000),    # the packet of 50 ms ago again, every tenth packet, for 4 s
    "dup": (3000, 2000),         # every packet twice, for 2 s
    "swap": (3000, 2000),        # adjacent packets swapped, for 2 s
    "resend2": (3000, 4000),     # the packet of 2 ms ago again, every tenth packet, for 4 s
}


def shifted(buf: bytes, dt_ns: int) -> bytes:
    b = bytearray(buf)
    t = int.from_bytes(b[_TS:_TS + 8], "little") + dt_ns
    b[_TS:_TS + 8] = t.to_bytes(8, "little")
    return bytes(b)


class FaultyNetwork:
    """Stands in for the virtual lidar's data socket (``sendto``); IMU packets pass untouched."""

    def __init__(self, sock, fault: str, state_path: Path):
        self.sock, self.fault, self.state_path = sock, fault, state_path
        self.start, self.span = FAULTS[fault]
        self.k = 0                                   # real point packets so far
        self.history: deque = deque(maxlen=5200)
        self.held = None
        self.counts = {"real_sent": 0, "injected": 0, "swapped": 0}
        self.done = False

    def __getattr__(self, name):
        return getattr(self.sock, name)

    def _send(self, buf, addr, injected=False):
        self.sock.sendto(buf, addr)
        self.counts["injected" if injected else "real_sent"] += 1

    def sendto(self, buf, addr):
        if buf[_DT] == IMU_DATA_TYPE:
            return self.sock.sendto(buf, addr)
        k, self.k = self.k, self.k + 1
        i = k - self.start
        self.history.append(buf)
        f = self.fault
        if 0 <= i < self.span:
            if f == "ahead" and i % 1000 == 0:
                self._send(buf, addr)
                self._send(shifted(buf, (50 + 50 * (i // 1000)) * 1_000_000), addr, injected=True)
            elif f == "old5s":
                self._send(buf, addr)
                for old in list(self.history)[-5001:-4901]:
                    self._send(old, addr, injected=True)
            elif f in ("resend50", "resend2") and i % 10 == 0:
                self._send(buf, addr)
                self._send(self.history[-1 - (50 if f == "resend50" else 2)], addr, injected=True)
            elif f == "dup":
                self._send(buf, addr)
                self._send(buf, addr, injected=True)
            elif f == "swap":
                if self.held is None:
                    self.held = buf
                else:
                    self._send(buf, addr)
                    self._send(self.held, addr)
                    self.held = None
                    self.counts["swapped"] += 1
            else:
                self._send(buf, addr)
        else:
            self._send(buf, addr)
        if not self.done and i >= self.span + 500:
            self.done = True
            self.state_path.write_text(json.dumps({"fault_done": True}))
        return len(buf)


def main(argv):
    scene_path, bport, truth, fault, state = argv
    from sim import virtual_lidar
    from sim.lidar_server import serve_scene
    from sim.scene import load_scene

    state = Path(state)
    net = {}
    init = virtual_lidar.VirtualLivox.__init__

    def patched(self, *a, **kw):
        init(self, *a, **kw)
        self._data = net["n"] = FaultyNetwork(self._data, fault, state)

    virtual_lidar.VirtualLivox.__init__ = patched
    counters = serve_scene(load_scene(scene_path), cmd_port=0, broadcast_addr=("127.0.0.1", int(bport)),
                           head_truth=truth, ready=lambda lidar: print("READY", flush=True))
    state.write_text(json.dumps({"fault_done": net["n"].done, **{k: int(v) for k, v in counters.items()},
                                 **net["n"].counts}))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
